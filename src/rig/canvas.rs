//! A content canvas: the content image a media server plays (a projection and view, its size)
//! and, for a panorama projected from a point (seed 001), that point. The rig holds the show's
//! canvas; a channel may have its own. The 2d exports point into it; the warp follows its
//! projection centre.

crate::projection::doc::view_document! {
    /// The content image a channel's 2d exports point into: a projection and view (as for
    /// `render`) and the image's size in pixels.
    pub struct Canvas {
        /// Width and height, pixels.
        pub size: [u32; 2],
        /// Where the content was shot, when it is a panorama projected from there onto the
        /// wall (seed 001) instead of shown around the eye: [x, y, z] in metres, inside the
        /// wall. The eye point itself is the plain panorama.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pub project_from: Option<[f64; 3]>,
    }
}

impl Default for Canvas {
    /// The whole sphere, equirectangular, 4096×2048.
    fn default() -> Self {
        Canvas {
            projection: "equirect".into(),
            params: crate::projection::Params {
                hfov: Some(360.0),
                vfov: Some(180.0),
                ..Default::default()
            },
            look_to: crate::projection::view::default_look_to(),
            look_up: crate::projection::view::default_look_up(),
            offaxis: [0.0; 3],
            zoom: 1.0,
            size: [4096, 2048],
            project_from: None,
        }
    }
}

impl Canvas {
    /// The canvas's view, checked; errors name the field.
    pub fn view(&self) -> crate::Result<crate::projection::View> {
        let [w, h] = self.size;
        if w == 0 || h == 0 || w > 65535 || h > 65535 {
            return Err(crate::Error::invalid(
                "/size",
                format!("must be 1–65535 pixels each way, got {w}×{h}"),
            ));
        }
        self.doc()
            .view(f64::from(h) / f64::from(w))
            .map_err(crate::projection::doc::pointer)
    }

    /// The panorama's projection centre checked against `rig`'s wall, if the canvas has one.
    pub fn centre(&self, rig: &crate::rig::Rig) -> crate::Result<Option<glam::DVec3>> {
        self.project_from
            .map(|c| rig.check_centre(glam::DVec3::from_array(c), "/project_from"))
            .transpose()
    }
}

/// How a frame lies on a canvas, derived from its projection and view (see
/// [`Canvas::layout`]): what [`Canvas::content`] builds, and what two canvases must share for
/// one decode to serve both.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Layout {
    /// An equirectangular panorama.
    Equirect {
        /// Degrees across.
        hfov: f64,
        /// Degrees up.
        vfov: f64,
        /// The canvas's orientation.
        turn: crate::projection::Orientation,
    },
    /// A cylindrical panorama.
    Cylindrical {
        /// Degrees around.
        hfov: f64,
        /// Degrees up.
        vfov: f64,
        /// The canvas's orientation.
        turn: crate::projection::Orientation,
    },
    /// An equidistant fisheye (a dome master, with a tilt) centred in the frame.
    Fisheye {
        /// Degrees across its circle.
        fov: f64,
        /// A dome master's forward tilt, degrees.
        tilt: Option<f64>,
        /// The circle's radius as a fraction of the frame's width.
        radius: f64,
        /// The frame's height ÷ width.
        aspect: f64,
        /// The canvas's orientation.
        turn: crate::projection::Orientation,
    },
}

impl Canvas {
    /// How a frame of `w`×`h` pixels lies on this canvas, for the content kinds the frame loop
    /// samples: equirectangular and cylindrical panoramas, equidistant fisheyes and dome
    /// masters, at zoom 1 and on axis. The frame's edges are the canvas's, as the 2d exports'
    /// coordinates say; a fisheye's frame must have the canvas's aspect (to a pixel) and the
    /// canvas square pixels, so that its circle stays round. Errors name the canvas's field.
    pub fn layout(&self, (w, h): (usize, usize)) -> crate::Result<Layout> {
        use crate::projection::Orientation;
        let view = self.view()?;
        if self.zoom != 1.0 || self.offaxis != [0.0; 3] {
            return Err(crate::Error::invalid(
                if self.zoom != 1.0 {
                    "/zoom"
                } else {
                    "/offaxis"
                },
                "a movie is laid out on canvases at zoom 1 with no off-axis vector",
            ));
        }
        let turn = Orientation::look(
            glam::DVec3::from_array(self.look_to),
            glam::DVec3::from_array(self.look_up),
        )
        .map_err(crate::projection::doc::pointer)?;
        let projection = view.projection();
        let form = projection.shader_form();
        let deg = f64::to_degrees;
        Ok(match (form.kind, form.radial) {
            (3, _) => Layout::Equirect {
                hfov: deg(2.0 * form.p[0]),
                vfov: deg(2.0 * form.p[1]),
                turn,
            },
            (1, _) => Layout::Cylindrical {
                hfov: deg(2.0 * form.p[0]),
                vfov: deg(2.0 * form.p[1].atan()),
                turn,
            },
            (4, 0) => {
                let (w, h) = (w as f64, h as f64);
                let [cw, ch] = self.size.map(f64::from);
                let (sx, sy, theta_max) = (form.p[0], form.p[1], form.p[2]);
                // θ = r per unit of s and t: sx radians over half the width, sy over half the
                // height; equal radians per pixel both ways keep the circle round.
                if (sx * ch / (sy * cw) - 1.0).abs() > 1e-6 {
                    return Err(crate::Error::invalid(
                        "/params",
                        format!(
                            "the fisheye's fields of view give its {cw}×{ch} canvas pixels of two \
                            sizes; a movie is laid out on a fisheye canvas with square pixels"
                        ),
                    ));
                }
                if (w * ch / cw - h).abs() > 1.0 {
                    return Err(crate::Error::invalid(
                        "/size",
                        format!(
                            "a fisheye's frame must have the canvas's aspect ratio: the frame is \
                            {w}×{h}, the canvas {cw}×{ch}"
                        ),
                    ));
                }
                Layout::Fisheye {
                    fov: deg(2.0 * theta_max).min(360.0),
                    tilt: (projection.name() == "domemaster")
                        .then(|| self.params.tilt.unwrap_or(0.0)),
                    radius: theta_max / sx / 2.0,
                    aspect: ch / cw,
                    turn,
                }
            }
            _ => {
                return Err(crate::Error::invalid(
                    "/projection",
                    format!(
                        "a movie is laid out on equirect, cylindrical, fisheye (equidistant) and \
                        domemaster canvases, not `{}`",
                        projection.name()
                    ),
                ));
            }
        })
    }

    /// The content an image shows laid out on this canvas (a movie's frame, say): see
    /// [`Canvas::layout`].
    pub fn content<T: crate::raster::Pixel>(
        &self,
        image: &crate::raster::Raster<T>,
    ) -> crate::Result<crate::content::Content<T>> {
        use crate::content::{Content, Fisheye};
        let layout = self.layout((image.width, image.height))?;
        let (content, turn) = match layout {
            Layout::Equirect { hfov, vfov, turn } => {
                // A derived field of view a rounding above the whole sphere is the whole sphere.
                (
                    Content::equirect(image, hfov.min(360.0), vfov.min(180.0)),
                    turn,
                )
            }
            Layout::Cylindrical { hfov, vfov, turn } => {
                (Content::cylindrical(image, hfov.min(360.0), vfov), turn)
            }
            Layout::Fisheye {
                fov,
                tilt,
                radius,
                turn,
                ..
            } => {
                let (w, h) = (image.width as f64, image.height as f64);
                let f = Fisheye {
                    fov,
                    tilt,
                    centre: Some([w / 2.0, h / 2.0]),
                    radius: Some(radius * w),
                };
                (Content::fisheye(image, &f), turn)
            }
        };
        Ok(content
            .map_err(|e| crate::Error::invalid("/params", e.to_string()))?
            .with_orientation(turn))
    }
}
