//! Camera files: OpenCV's `cameraMatrix` + `distCoeffs` in its FileStorage YAML or JSON, and
//! mrcal's `.cameramodel` (a Python-literal dictionary). Writers go through the atomic writer.
//!
//! OpenCV files do not say whether four coefficients are a pinhole's (k1 k2 p1 p2) or a
//! fisheye's (k1..k4): the caller says which.

use super::{Lens, LensModel};
use crate::error::{Error, Result};
use crate::image_io::atomic_write;
use serde_json::Value;
use std::io::Write;
use std::path::Path;

const CAMERA_KEYS: [&str; 3] = ["cameraMatrix", "camera_matrix", "K"];
const DIST_KEYS: [&str; 4] = ["distCoeffs", "dist_coeffs", "distortion_coefficients", "D"];

/// A lens with what mrcal's files carry beside it.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    /// The lens: model and intrinsics.
    pub lens: Lens,
    /// Width and height in pixels.
    pub imager_size: Option<[u32; 2]>,
    /// mrcal's `rt_cam_ref`: Rodrigues rotation then translation, reference → camera.
    pub extrinsics: Option<[f64; 6]>,
}

fn bad(path: &Path, why: impl std::fmt::Display + 'static) -> Error {
    Error::file(path, why)
}

/// Reads an OpenCV FileStorage file (YAML or JSON) holding a camera matrix and, optionally,
/// distortion coefficients (4, 5, 8, 12 or 14; or 4 for a fisheye).
pub fn read_opencv(path: &Path, fisheye: bool) -> Result<Lens> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, e))?;
    let matrix = |keys: &[&str]| -> Result<Option<(usize, usize, Vec<f64>)>> {
        for key in keys {
            let found = if text.trim_start().starts_with('{') {
                json_matrix(&text, key).map_err(|e| bad(path, e))?
            } else {
                yaml_matrix(&text, key).map_err(|e| bad(path, e))?
            };
            if found.is_some() {
                return Ok(found);
            }
        }
        Ok(None)
    };
    let (rows, cols, k) = matrix(&CAMERA_KEYS)?
        .ok_or_else(|| bad(path, "no camera matrix (cameraMatrix or camera_matrix)"))?;
    if (rows, cols) != (3, 3) || k.len() != 9 {
        return Err(bad(
            path,
            format!("the camera matrix must be 3×3, got {rows}×{cols}"),
        ));
    }
    if k[1] != 0.0 {
        return Err(bad(
            path,
            "the camera matrix has skew; OpenCV's models ignore it, so it would be lost",
        ));
    }
    let d = matrix(&DIST_KEYS)?.map(|m| m.2).unwrap_or_default();
    let model = match (fisheye, d.len()) {
        (true, 4) => LensModel::OpenCvFisheye,
        (true, n) => {
            return Err(bad(
                path,
                format!("a fisheye takes 4 distortion coefficients, got {n}"),
            ));
        }
        (false, 0) => LensModel::Pinhole,
        (false, n @ (4 | 5 | 8 | 12 | 14)) => LensModel::OpenCv(n as u8),
        (false, n) => {
            return Err(bad(
                path,
                format!("OpenCV takes 4, 5, 8, 12 or 14 distortion coefficients, got {n}"),
            ));
        }
    };
    let mut intrinsics = vec![k[0], k[4], k[2], k[5]];
    intrinsics.extend(d);
    Lens::new(model, intrinsics).map_err(|e| bad(path, e))
}

/// Writes `lens` as OpenCV FileStorage YAML, or JSON when `path` ends in `.json`.
pub fn write_opencv(path: &Path, lens: &Lens) -> Result<()> {
    let i = lens.intrinsics();
    let d: &[f64] = match lens.model() {
        LensModel::Pinhole => &[],
        LensModel::OpenCv(_) | LensModel::OpenCvFisheye => &i[4..],
        other => {
            return Err(Error::invalid(
                "model",
                format!("{other} has no OpenCV form"),
            ));
        }
    };
    let k = [i[0], 0.0, i[2], 0.0, i[1], i[3], 0.0, 0.0, 1.0];
    let json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let text = if json {
        let m = |rows: usize, cols: usize, data: &[f64]| serde_json::json!({"type_id": "opencv-matrix", "rows": rows, "cols": cols, "dt": "d", "data": data});
        let mut doc = serde_json::Map::new();
        doc.insert("cameraMatrix".into(), m(3, 3, &k));
        if !d.is_empty() {
            doc.insert("distCoeffs".into(), m(1, d.len(), d));
        }
        serde_json::to_string_pretty(&Value::Object(doc)).expect("numbers serialise")
    } else {
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let block = |name: &str, rows: usize, cols: usize, v: &[f64]| {
            format!(
                "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n",
                list(v)
            )
        };
        let mut s = String::from("%YAML:1.0\n---\n");
        s += &block("cameraMatrix", 3, 3, &k);
        if !d.is_empty() {
            s += &block("distCoeffs", 1, d.len(), d);
        }
        s
    };
    atomic_write(path, |f| {
        f.write_all(text.as_bytes()).map_err(|e| bad(path, e))
    })
}

fn json_matrix(
    text: &str,
    key: &str,
) -> std::result::Result<Option<(usize, usize, Vec<f64>)>, String> {
    let doc: Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let Some(m) = doc.get(key) else {
        return Ok(None);
    };
    let num = |k: &str| {
        m.get(k)
            .and_then(Value::as_u64)
            .map(|v| v as usize)
            .ok_or(format!("{key}.{k} is missing"))
    };
    let data = m
        .get("data")
        .and_then(Value::as_array)
        .ok_or(format!("{key}.data is missing"))?
        .iter()
        .map(|v| v.as_f64().ok_or(format!("{key}.data holds a non-number")))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    matrix_shape(key, num("rows")?, num("cols")?, data).map(Some)
}

fn matrix_shape(
    key: &str,
    rows: usize,
    cols: usize,
    data: Vec<f64>,
) -> std::result::Result<(usize, usize, Vec<f64>), String> {
    if rows.checked_mul(cols) != Some(data.len()) {
        return Err(format!(
            "{key} is {rows}×{cols} but holds {} numbers",
            data.len()
        ));
    }
    if let Some(v) = data.iter().find(|v| !v.is_finite()) {
        return Err(format!("{key} holds {v}"));
    }
    Ok((rows, cols, data))
}

/// The `!!opencv-matrix` block under top-level `key` of a FileStorage YAML file.
fn yaml_matrix(
    text: &str,
    key: &str,
) -> std::result::Result<Option<(usize, usize, Vec<f64>)>, String> {
    let lines: Vec<&str> = text.lines().collect();
    let Some(start) = lines
        .iter()
        .position(|l| l.split_once(':').is_some_and(|(k, _)| k == key))
    else {
        return Ok(None);
    };
    // The block runs until the next line that starts at column 0.
    let end = lines[start + 1..]
        .iter()
        .position(|l| !l.is_empty() && !l.starts_with([' ', '\t']))
        .map_or(lines.len(), |n| start + 1 + n);
    let block = lines[start + 1..end].join("\n");
    let field = |name: &str| -> Option<&str> {
        block.lines().find_map(|l| {
            l.trim()
                .strip_prefix(name)
                .and_then(|r| r.strip_prefix(':'))
                .map(str::trim)
        })
    };
    let count = |name: &str| {
        field(name)
            .and_then(|v| v.parse::<usize>().ok())
            .ok_or(format!("{key}.{name} is missing"))
    };
    let (rows, cols) = (count("rows")?, count("cols")?);
    let open = block.find('[').ok_or(format!("{key}.data is missing"))?;
    let close = block[open..]
        .find(']')
        .ok_or(format!("{key}.data is not closed"))?
        + open;
    let data = block[open + 1..close]
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            let s = if s.starts_with('.') || s.starts_with("-.") {
                s.replacen('.', "0.", 1)
            } else {
                s.to_string()
            };
            s.parse::<f64>()
                .map_err(|_| format!("{key}.data holds `{s}`"))
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    matrix_shape(key, rows, cols, data).map(Some)
}

/// Reads an mrcal `.cameramodel`.
pub fn read_cameramodel(path: &Path) -> Result<CameraModel> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, e))?;
    let json = python_literal_to_json(&text);
    let doc: Value =
        serde_json::from_str(&json).map_err(|e| bad(path, format!("not a cameramodel: {e}")))?;
    let model: LensModel = doc
        .get("lensmodel")
        .and_then(Value::as_str)
        .ok_or_else(|| bad(path, "no 'lensmodel'"))?
        .parse()
        .map_err(|e| bad(path, e))?;
    let numbers = |key: &str| -> Result<Option<Vec<f64>>> {
        match doc.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_array()
                .and_then(|a| a.iter().map(Value::as_f64).collect::<Option<Vec<_>>>())
                .map(Some)
                .ok_or_else(|| bad(path, format!("'{key}' must be a list of numbers"))),
        }
    };
    let intrinsics = numbers("intrinsics")?.ok_or_else(|| bad(path, "no 'intrinsics'"))?;
    let lens = Lens::new(model, intrinsics).map_err(|e| bad(path, e))?;
    let imager_size = match numbers("imagersize")? {
        None => None,
        Some(v)
            if v.len() == 2
                && v.iter()
                    .all(|x| (1.0..=f64::from(u32::MAX)).contains(x) && x.fract() == 0.0) =>
        {
            Some([v[0] as u32, v[1] as u32])
        }
        Some(_) => return Err(bad(path, "'imagersize' must be two positive whole numbers")),
    };
    let extrinsics = match numbers("extrinsics")? {
        None => None,
        Some(v) if v.len() == 6 => Some([v[0], v[1], v[2], v[3], v[4], v[5]]),
        Some(v) => {
            return Err(bad(
                path,
                format!(
                    "'extrinsics' must hold 6 numbers (rt_cam_ref), got {}",
                    v.len()
                ),
            ));
        }
    };
    Ok(CameraModel {
        lens,
        imager_size,
        extrinsics,
    })
}

/// Writes an mrcal `.cameramodel`; mrcal needs the imager size.
pub fn write_cameramodel(path: &Path, m: &CameraModel) -> Result<()> {
    let size = m.imager_size.ok_or_else(|| {
        Error::invalid("imagersize", "an mrcal cameramodel needs the imager size")
    })?;
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let text = format!(
        "# written by omniwarp\n{{\n    'lensmodel': '{}',\n    'intrinsics': [ {} ],\n    'imagersize': [ {}, {} ],\n    'extrinsics': [ {} ],\n}}\n",
        m.lens.model(),
        list(m.lens.intrinsics()),
        size[0],
        size[1],
        list(&m.extrinsics.unwrap_or([0.0; 6])),
    );
    atomic_write(path, |f| {
        f.write_all(text.as_bytes()).map_err(|e| bad(path, e))
    })
}

/// mrcal writes its models as Python literals: '#' comments, single quotes, trailing commas.
fn python_literal_to_json(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_string = false;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                in_string = !in_string;
                out.push('"');
            }
            '#' if !in_string => {
                while chars.peek().is_some_and(|&n| n != '\n') {
                    chars.next();
                }
            }
            _ => out.push(c),
        }
    }
    // Drop commas that directly precede a closing bracket or brace.
    let mut cleaned = String::with_capacity(out.len());
    let bytes: Vec<char> = out.chars().collect();
    for (i, &c) in bytes.iter().enumerate() {
        if c == ',' {
            let next = bytes[i + 1..].iter().find(|n| !n.is_whitespace());
            if matches!(next, Some(']') | Some('}')) {
                continue;
            }
        }
        cleaned.push(c);
    }
    cleaned
}
