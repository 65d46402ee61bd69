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
