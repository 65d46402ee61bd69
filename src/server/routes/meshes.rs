//! Mesh screens over HTTP. A rig's mesh screen names a file the daemon reads from its own
//! directories only (the data directory's `meshes/`, or `--assets`), never a path a client
//! chooses; a mesh gets there by `PUT /v1/meshes/{name}` with the OBJ text as the body. A
//! name, once uploaded, keeps its contents (a different upload under it is a 409), so cached
//! warps keyed by the rig document stay true to the mesh they were computed from.

use crate::image_io::{Access, atomic_write_as, create_private_dir_durably};
use crate::server::ApiError;
use crate::server::http::jobs::run_write;
use crate::server::http::state::AppState;
use crate::server::storage::store::mesh_name;
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
        Mesh::new(triangles).map_err(|e| ApiError::Invalid {
            field: "body".into(),
            reason: e.reason(),
        })?;
        let meshes = dir.join("meshes");
        let path = meshes.join(&name);
        create_private_dir_durably(&meshes)?;
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
