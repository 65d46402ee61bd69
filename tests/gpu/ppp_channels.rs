//! Piecewise perspective projection through a projector channel's warp map (the pieces cut
//! from the map, not from a view), and the daemon's scene previews that draw with it: `render?
//! scene=…&method=cube|ppp|exact|auto`.

use crate::common;

use common::server::{call, demo_rig, demo_state, get, json, state};
use omniwarp::raster::{Raster, psnr};
use omniwarp::rig::Rig;
use omniwarp::scene::ppp::{Directions, Pieces, Tolerance};

fn demo() -> Rig {
    Rig::from_doc(demo_rig()).unwrap()
}

/// Every mapped pixel of every demo channel is drawn by a piece, no unmapped one is, and the
/// pieces' directions stay within the tolerance of the map's own, the wall's edge included
/// (where the pieces' corners lie outside the map and are continued from it).
#[test]
fn pieces_cut_from_a_warp_map_cover_it_within_the_tolerance() {
    let rig = demo();
    for ch in &rig.channels {
        let map = rig.warp(ch).map;
        let (w, h) = map.size();
        let t = 0.25;
        let (pieces, d) = Pieces::for_tolerance_on(&map, Tolerance::Pixels(t)).unwrap();
        assert!(d.pixels <= t, "{}: {d:?}", ch.id);
        let mut worst: f64 = 0.0;
        let mut mapped = 0;
        for j in 0..h {
            for i in 0..w {
                let truth = map.direction(i as usize, j as usize);
                let drawn = pieces.ray(i, j);
                assert_eq!(
                    truth.is_some(),
                    drawn.is_some(),
                    "{}: pixel {i},{j} mapped {} drawn {}",
                    ch.id,
                    truth.is_some(),
                    drawn.is_some()
                );
                if let (Some(a), Some(b)) = (truth, drawn) {
                    worst = worst.max(a.angle_between(b));
                    mapped += 1;
                }
            }
        }
        // A map that lost its coverage would pass the checks above over nothing.
        assert!(
            mapped as f64 >= 0.5 * f64::from(w * h),
            "{}: {mapped} pixels mapped",
            ch.id
        );
        assert!(worst <= t * pieces.pitch, "{}: {worst}", ch.id);
        eprintln!(
            "{}: {}×{} cells, {} pieces, {:.3} px",
            ch.id,
            pieces.cols,
            pieces.rows,
            pieces.pieces.len(),
            worst / pieces.pitch
        );
    }
}

fn decode(bytes: &[u8]) -> Raster<[u8; 4]> {
    let img = image::load_from_memory(bytes).unwrap().to_rgba8();
    Raster {
        width: img.width() as usize,
        height: img.height() as usize,
        data: img.pixels().map(|p| p.0).collect(),
    }
}

/// The number that follows `marker` in a header's text.
fn number_after(text: &str, marker: &str) -> f64 {
    let rest = text
        .split(marker)
        .nth(1)
        .unwrap_or_else(|| panic!("{text}"));
    rest.split(' ').next().unwrap().parse().unwrap()
}

async fn scene_preview(
    s: &std::sync::Arc<omniwarp::server::AppState>,
    query: &str,
) -> (Raster<[u8; 4]>, String) {
    let (st, headers, body) = call(s, get(&format!("/v1/channels/centre/render?{query}"))).await;
    assert_eq!(st, 200, "{query}: {}", String::from_utf8_lossy(&body));
    let said = headers["x-omniwarp-method"].to_str().unwrap().to_string();
    (decode(&body), said)
}

/// The demo rig's centre channel at a quarter of its size showing the small city: PPP cut to
/// 0.25 px is as close to the exact ray cast as its error allows, closer than the cube map at
/// its default face; the GPU and its CPU twin agree; auto picks one of the two and says which.
#[tokio::test(flavor = "multi_thread")]
async fn scene_previews_draw_by_the_method_asked() {
    let s = demo_state();
    let base = "scene=city:small&scale=4";
    let (exact, said) = scene_preview(&s, &format!("{base}&method=exact")).await;
    assert!(said.starts_with("exact"), "{said}");
    let mut shown = Vec::new();
    for method in ["ppp", "cube"] {
        let (img, said) = scene_preview(&s, &format!("{base}&method={method}")).await;
        assert!(said.starts_with(method), "{said}");
        let db = psnr(&img, &exact, 255.0, |_, _| true);
        eprintln!("{said}: {db:.1} dB against the exact ray cast");
        shown.push((db, img, said));
    }
    let (ppp, cube) = (&shown[0], &shown[1]);
    // The header says the error reached, within the default 0.25 px.
    let px = number_after(&ppp.2, " deg (");
    assert!(px <= 0.25, "{}", ppp.2);
    assert!(
        ppp.0 >= 30.0 && ppp.0 > cube.0,
        "ppp {:.1} dB, cube {:.1} dB",
        ppp.0,
        cube.0
    );
    let (gpu, said) = scene_preview(&s, &format!("{base}&method=ppp&renderer=gpu")).await;
    assert!(
        said.ends_with("gpu") && said.contains("replication"),
        "{said}"
    );
    let twins = psnr(&gpu, &ppp.1, 255.0, |_, _| true);
    assert!(twins >= 40.0, "GPU against its CPU twin: {twins:.1} dB");
    let (_, said) = scene_preview(&s, &format!("{base}&method=auto&tolerance=0.05deg")).await;
    assert!(
        said.starts_with("auto: ppp") || said.starts_with("auto: cube"),
        "{said}"
    );
    let deg = number_after(&said, "max error ");
    assert!(deg <= 0.05, "{said}");
}

/// Each wrong or conflicting scene parameter is refused naming it.
#[tokio::test]
async fn scene_preview_parameters_are_checked() {
    let s = state(None, None);
    for (query, field) in [
        ("scene=city:large", "scene"),
        ("scene=/etc/passwd", "scene"),
        ("scene=city:small&method=raster", "method"),
        ("method=ppp", "method"),
        ("tolerance=1px", "tolerance"),
        ("scene=city:small&method=cube&tolerance=1px", "tolerance"),
        ("scene=city:small&method=ppp&tolerance=0.25", "tolerance"),
        ("scene=city:small&method=ppp&tolerance=-1px", "tolerance"),
        ("scene=city:small&method=ppp&tolerance=1e-9px", "tolerance"),
        ("scene=city:small&method=ppp&face=256", "face"),
        ("scene=city:small&format=exr", "format"),
        ("scene=city:small&filter=bicubic", "filter"),
        ("scene=city:small&content=checker", "content"),
        ("scene=city:small&renderer=fast", "renderer"),
    ] {
        let (st, _, body) = call(&s, get(&format!("/v1/channels/left/render?{query}"))).await;
        assert_eq!(st, 400, "{query}");
        assert_eq!(
            json(&body)["field"],
            field,
            "{query}: {}",
            String::from_utf8_lossy(&body)
        );
    }
}
