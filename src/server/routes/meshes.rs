//! Mesh screens over HTTP. A rig's mesh screen names a file the daemon reads from its own
//! directories only (the data directory's `meshes/`, or `--assets`), never a path a client
//! chooses; a mesh gets there by `PUT /v1/meshes/{name}` with the OBJ text as the body. A
//! name, while uploaded, keeps its contents (a different upload under it is a 409: of two
//! uploads racing for a name one wins and the other is told). `DELETE` removes a mesh the
//! current rig does not use; the uploads together stay within a count and a size quota.

use crate::image_io::{Access, atomic_write_as, create_private_dir_durably};
use crate::server::ApiError;
use crate::server::http::jobs::run_write;
use crate::server::http::state::AppState;
use crate::server::storage::store::mesh_name;
use crate::surface::Screen;
use crate::surface::{Mesh, parse_obj_triangles};
use axum::Json;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

/// The meshes a rig can name.
pub async fn list(State(s): State<Arc<AppState>>) -> Result<Json<serde_json::Value>, ApiError> {
    let dirs = s.store.meshes.clone();
    let names = tokio::task::spawn_blocking(move || {
        let mut names: Vec<String> = [dirs.data, dirs.assets]
            .into_iter()
            .flatten()
            .filter_map(|d| std::fs::read_dir(d).ok())
            .flat_map(|entries| entries.flatten())
            .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|n| mesh_name(n).is_ok())
            .collect();
        names.sort();
        names.dedup();
        names
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(Json(serde_json::json!({"meshes": names})))
}

/// Stores an OBJ file after reading it as a mesh screen would be read.
pub async fn put(
    State(s): State<Arc<AppState>>,
    Path(name): Path<String>,
    body: Bytes,
) -> Result<Response, ApiError> {
    mesh_name(&name).map_err(|e| ApiError::Invalid {
        field: "name".into(),
        reason: e.reason(),
    })?;
    let Some(dir) = s.store.dir.clone() else {
        return Err(ApiError::refused(
            StatusCode::CONFLICT,
            None,
            "this daemon keeps no files: start it with --data to upload meshes",
        ));
    };
    let answer = serde_json::json!({"name": name});
    let created = run_write(&s, move |_| {
        let text = std::str::from_utf8(&body).map_err(|_| ApiError::Invalid {
            field: "body".into(),
            reason: "an OBJ file must be UTF-8 text".into(),
        })?;
        let triangles = parse_obj_triangles(text).map_err(|e| ApiError::Invalid {
            field: "body".into(),
            reason: e.reason(),
        })?;
        // Checked as a screen would take it; its tree is built when a rig names it, within the
        // memory budget, not for every upload.
        Mesh::check(&triangles).map_err(|e| ApiError::Invalid {
            field: "body".into(),
            reason: e.reason(),
        })?;
        let meshes = dir.join("meshes");
        let path = meshes.join(&name);
        create_private_dir_durably(&meshes)?;
        within_quota(&meshes, &name, body.len() as u64)?;
        // Created only if absent, in one step: of two uploads racing for a name, one makes
        // the file and the other finds it.
        let created = atomic_write_as(&path, Access::Private, false, |f| {
            std::io::Write::write_all(f, &body).map_err(|e| crate::Error::file(&path, e))
        })?;
        if created || std::fs::read(&path).is_ok_and(|old| old == body) {
            return Ok(created);
        }
        Err(ApiError::refused(
            StatusCode::CONFLICT,
            Some("name"),
            format!("mesh `{name}` exists with other contents; upload under a new name"),
        ))
    })
    .await?;
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((status, Json(answer)).into_response())
}

/// Refuses (507) an upload of `size` bytes under `name` that would take the uploads past
/// [`crate::limits::MESHES`] files or [`crate::limits::MESH_STORE_BYTES`] bytes; a name already
/// there is counted once. Uploads racing each other may pass it together, by one body each.
fn within_quota(meshes: &std::path::Path, name: &str, size: u64) -> Result<(), ApiError> {
    let (mut count, mut bytes) = (1usize, size);
    let entries = std::fs::read_dir(meshes).map_err(|e| crate::Error::file(meshes, e))?;
    for e in entries.flatten() {
        let file = e.file_name();
        let counted = file
            .to_str()
            .is_some_and(|n| mesh_name(n).is_ok() && n != name);
        if let Ok(m) = e.metadata()
            && counted
            && m.is_file()
        {
            count += 1;
            bytes = bytes.saturating_add(m.len());
        }
    }
    let (most, quota) = (crate::limits::MESHES, crate::limits::MESH_STORE_BYTES);
    if count > most || bytes > quota {
        return Err(ApiError::refused(
            StatusCode::INSUFFICIENT_STORAGE,
            Some("name"),
            format!(
                "the uploaded meshes would be {count} files and {} MiB, above the quota of {most} \
                 files and {} MiB; delete one with DELETE /v1/meshes/{{name}}",
                bytes >> 20,
                quota >> 20
            ),
        ));
    }
    Ok(())
}

/// Removes an uploaded mesh. A mesh the current rig shows is refused (409): change the rig
/// first. Earlier rig revisions that name it can no longer be reverted to until it is uploaded
/// again. Meshes in `--assets` are the operator's and are not touched.
pub async fn delete(
    State(s): State<Arc<AppState>>,
    Path(name): Path<String>,
) -> Result<Response, ApiError> {
    mesh_name(&name).map_err(|e| ApiError::Invalid {
        field: "name".into(),
        reason: e.reason(),
    })?;
    let missing = || ApiError::NotFound(format!("no uploaded mesh `{name}`"));
    let Some(dir) = s.store.dir.clone() else {
        return Err(missing());
    };
    // No rig can take the mesh up between the check and the removal.
    let writer = s.store.rig_writer.clone().lock_owned().await;
    let (rig, _) = s.store.snapshot();
    if let Screen::Mesh { obj, .. } = &rig.doc.screen
        && *obj == name
    {
        return Err(ApiError::refused(
            StatusCode::CONFLICT,
            Some("name"),
            format!("the current rig's screen is mesh `{name}`; PUT a rig without it first"),
        ));
    }
    let path = dir.join("meshes").join(&name);
    let removed = tokio::task::spawn_blocking(move || {
        let _writer = writer;
        match std::fs::remove_file(&path) {
            // The removal is durable before it is acknowledged, as an upload is.
            Ok(()) => std::fs::File::open(path.parent().expect("in meshes/"))
                .and_then(|d| d.sync_all())
                .map(|()| true)
                .map_err(|e| crate::Error::file(&path, e)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
            Err(e) => Err(crate::Error::file(&path, e)),
        }
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    if !removed {
        return Err(missing());
    }
    Ok(StatusCode::NO_CONTENT.into_response())
}
