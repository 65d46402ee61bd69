//! A view as files and requests describe it: a projection by name with its parameters, and the
//! view transform (look-to, look-up, off-axis vector, zoom). One type, [`ViewDoc`], for the
//! fields every such document shares; `view_document!` declares a document that is those
//! fields plus its own (a tile screen's `source` adds the aspect it was sampled for, a content
//! canvas its size), written flat as one JSON object with unknown fields refused.

use super::{Orientation, Params, View};
use crate::error::{Error, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// A projection and view transform: angles in degrees, vectors as [x, y, z].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewDoc {
    /// The projection's name or alias: `flat`, `cylindrical`, `equirect`, `fisheye`, `domemaster`,
    /// … (see [`crate::projection::REGISTRY`]).
    pub projection: String,
    /// Its parameters, angles in degrees; one the projection does not take is refused. All
    /// unset when absent.
    #[serde(default)]
    pub params: Params,
    /// Look-to LT, [x, y, z], any non-zero length: where the projection's forward (−z) points in
    /// the world. [0, 0, −1] when absent.
    #[serde(default = "super::view::default_look_to")]
    pub look_to: [f64; 3],
    /// Look-up LU, [x, y, z]: the view's up, not parallel to `look_to` (need not be perpendicular
    /// to it). [0, 1, 0] when absent.
    #[serde(default = "super::view::default_look_up")]
    pub look_up: [f64; 3],
    /// Off-axis vector O of the seeds, [x, y, z], shorter than 1; zero when absent.
    #[serde(default)]
    pub offaxis: [f64; 3],
    /// Scale of the screen coordinates before δP (V = C·δP(F·zoom) − O): above 1 shows more of the
    /// projection, below 1 less; 0.001–1000, 1 when absent.
    #[serde(default = "one")]
    pub zoom: f64,
}

pub(crate) fn one() -> f64 {
    1.0
}

impl ViewDoc {
    /// The plain projection, looking ahead.
    pub fn new(projection: &str, params: Params) -> Self {
        ViewDoc {
            projection: projection.into(),
            params,
            look_to: super::view::default_look_to(),
            look_up: super::view::default_look_up(),
            offaxis: [0.0; 3],
            zoom: 1.0,
        }
    }

    /// The view for an output of height / width `aspect`. Errors name the parameter as the
    /// library does (`hfov`, `look_to`); [`pointer()`] turns that into the document's JSON pointer.
    pub fn view(&self, aspect: f64) -> Result<View> {
        let p = super::build(&self.projection, &self.params, aspect)?;
        let c = Orientation::look(
            DVec3::from_array(self.look_to),
            DVec3::from_array(self.look_up),
        )?;
        View::new(p, c, DVec3::from_array(self.offaxis), self.zoom)
    }
}

/// An error of [`ViewDoc::view`] with its field as a JSON pointer into the document
/// (`/params/hfov`, `/zoom`).
pub fn pointer(e: Error) -> Error {
    let (name, reason) = match e {
        Error::Invalid { name, reason } => (name, reason),
        other => (String::new(), other.to_string()),
    };
    // The library names the view's vectors as the command line spells them.
    let name = match name.trim_start_matches('/') {
        "look-to" => "look_to",
        "look-up" => "look_up",
        other => other,
    };
    let params = [
        "hfov", "vfov", "fov", "tilt", "left", "right", "bottom", "top",
    ];
    let at = if params.contains(&name) {
        format!("/params/{name}")
    } else {
        format!("/{name}")
    };
    Error::invalid(at, reason)
}

/// Declares `struct $name` holding the fields of [`ViewDoc`] and `$extra` fields of its own,
/// serialised flat, with `doc()` to get the [`ViewDoc`] back. (Serde's `flatten` would lose
/// both the refusal of unknown fields and the path of a bad field, hence a macro.)
macro_rules! view_document {
    ($(#[$m:meta])* pub struct $name:ident { $($(#[$fm:meta])* pub $field:ident: $ty:ty,)* }) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            /// The projection's name or alias: `flat`, `cylindrical`, `equirect`, `fisheye`,
            /// `domemaster`, … (see [`crate::projection::REGISTRY`]).
            pub projection: String,
            /// Its parameters, angles in degrees; one the projection does not take is refused.
            /// All unset when absent.
            #[serde(default)]
            pub params: crate::projection::Params,
            /// Look-to LT, [x, y, z], any non-zero length: where the projection's forward (−z)
            /// points in the world. [0, 0, −1] when absent.
            #[serde(default = "crate::projection::view::default_look_to")]
            pub look_to: [f64; 3],
            /// Look-up LU, [x, y, z]: the view's up, not parallel to `look_to` (need not be
            /// perpendicular to it). [0, 1, 0] when absent.
            #[serde(default = "crate::projection::view::default_look_up")]
            pub look_up: [f64; 3],
            /// Off-axis vector O of the seeds, [x, y, z], shorter than 1; zero when absent.
            #[serde(default)]
            pub offaxis: [f64; 3],
            /// Scale of the screen coordinates before δP (V = C·δP(F·zoom) − O): above 1 shows
            /// more of the projection, below 1 less; 0.001–1000, 1 when absent.
            #[serde(default = "crate::projection::doc::one")]
            pub zoom: f64,
            $($(#[$fm])* pub $field: $ty,)*
        }

        impl $name {
            /// The view description without this document's own fields.
            pub fn doc(&self) -> crate::projection::ViewDoc {
                crate::projection::ViewDoc {
                    projection: self.projection.clone(),
                    params: self.params,
                    look_to: self.look_to,
                    look_up: self.look_up,
                    offaxis: self.offaxis,
                    zoom: self.zoom,
                }
            }

            /// This document with `view`'s fields and its own.
            pub fn from_doc(view: crate::projection::ViewDoc, $($field: $ty),*) -> Self {
                $name {
                    projection: view.projection,
                    params: view.params,
                    look_to: view.look_to,
                    look_up: view.look_up,
                    offaxis: view.offaxis,
                    zoom: view.zoom,
                    $($field,)*
                }
            }
        }
    };
}
pub(crate) use view_document;
