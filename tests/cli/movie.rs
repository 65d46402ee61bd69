//! Movies and image sequences through `omniwarp render`, against `omniwarp render` of each
//! frame's still, with ffmpeg (installed by scripts/test from Debian's packages) making the
//! clips and reading the results back.

use crate::common::read_u8;
use omniwarp::raster::{Raster, psnr};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn run(dir: &Path, program: &str, args: &[&str]) -> (bool, String) {
    let program = if program == "omniwarp" {
        env!("CARGO_BIN_EXE_omniwarp")
    } else {
        program
    };
    let out = Command::new(program)
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("{program}: {e} (scripts/test installs ffmpeg)"));
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn ok(dir: &Path, program: &str, args: &[&str]) -> String {
    let (ok, err) = run(dir, program, args);
    assert!(ok, "{program} {}: {err}", args.join(" "));
    err
}

fn ffmpeg(dir: &Path, args: &str) {
    let mut all = vec!["-hide_banner", "-loglevel", "error", "-y"];
    all.extend(args.split_whitespace());
    ok(dir, "ffmpeg", &all);
}

/// The field of `ffprobe` for the first stream of `kind` (v or a).
fn probe(dir: &Path, file: &str, kind: &str, field: &str) -> String {
    let out = Command::new("ffprobe")
        .current_dir(dir)
        .args(["-v", "error", "-select_streams", &format!("{kind}:0")])
        .args([
            "-show_entries",
            &format!("stream={field}"),
            "-of",
            "csv=p=0",
            file,
        ])
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

/// Every frame of a movie as PNG files `prefix-%03d.png`, numbered from 1; their paths.
fn frames(dir: &Path, movie: &str, prefix: &str) -> Vec<PathBuf> {
    ffmpeg(
        dir,
        &format!("-i {movie} -start_number 1 {prefix}-%03d.png"),
    );
    let mut v: Vec<PathBuf> = (1..)
        .map(|k| dir.join(format!("{prefix}-{k:03}.png")))
        .take_while(|p| p.exists())
        .collect();
    v.sort();
    v
}

/// A 12-frame equirect clip with a tone, 15 fps, 256×128: testsrc2 (frame counter drawn in)
/// stored in `format` (yuv420p or rgb24 via FFV1).
fn clip(dir: &Path, name: &str, pix_fmt: &str) {
    ffmpeg(
        dir,
        &format!(
            "-f lavfi -i testsrc2=size=256x128:rate=15 -f lavfi -i sine=frequency=440:sample_rate=48000 \
             -frames:v 12 -t 0.8 -pix_fmt {pix_fmt} -c:v ffv1 -c:a pcm_s16le -timecode 01:00:00:00 {name}"
        ),
    );
}

const CYLINDER: [&str; 8] = [
    "--projection",
    "cylindrical",
    "--hfov",
    "270",
    "--vfov",
    "90",
    "--size",
    "192x64",
];

/// An image sequence in, a lossless movie out: every frame is exactly the still render of its
/// source frame, frame count, rate and timecode carried over.
#[test]
fn a_sequence_through_the_cylinder_equals_each_frames_still() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "src.mkv", "rgb24");
    let sources = frames(d, "src.mkv", "in");
    assert_eq!(sources.len(), 12);
    let mut args = vec![
        "render",
        "--content",
        "in-%03d.png",
        "--content-format",
        "equirect",
        "--frame-rate",
        "15",
    ];
    args.extend(CYLINDER);
    args.extend(["--out", "out.nut"]);
    ok(d, "omniwarp", &args);
    assert_eq!(probe(d, "out.nut", "v", "codec_name"), "ffv1");
    assert_eq!(probe(d, "out.nut", "v", "r_frame_rate"), "15/1");
    let outs = frames(d, "out.nut", "out");
    assert_eq!(outs.len(), 12);
    // The throughput sink warps every frame and writes nothing.
    let files = || std::fs::read_dir(d).unwrap().count();
    let before = files();
    let last = args.len() - 1;
    args[last] = "null:";
    let err = ok(d, "omniwarp", &args);
    assert!(err.contains("12 frames"), "{err}");
    assert_eq!(files(), before);
    for (k, (src, out)) in sources.iter().zip(&outs).enumerate() {
        let mut args = vec![
            "render",
            "--content",
            src.to_str().unwrap(),
            "--content-format",
            "equirect",
        ];
        args.extend(CYLINDER);
        args.extend(["--out", "still.png"]);
        ok(d, "omniwarp", &args);
        let (a, b) = (read_u8(out), read_u8(&d.join("still.png")));
        let rgb = |r: &Raster<[u8; 4]>| -> Vec<[u8; 3]> {
            r.data.iter().map(|p| [p[0], p[1], p[2]]).collect()
        };
        assert!(rgb(&a) == rgb(&b), "frame {} differs from its still", k + 1);
    }
}

/// A 4:2:0 movie with sound in, warped in Y′CbCr and stored losslessly: each frame is the still
/// render of the frame ffmpeg decodes, stored as 4:2:0; frame count, rate, the
/// sound stream and the timecode equal; and one decode feeding three rig channels gives the
/// frames of three separate runs.
#[test]
fn a_movie_keeps_its_rate_sound_and_timecode_and_one_decode_feeds_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "src.mkv", "yuv420p");
    let mut args = vec![
        "render",
        "--content",
        "src.mkv",
        "--content-format",
        "equirect",
    ];
    args.extend(CYLINDER);
    args.extend([
        "--encoder",
        "ffv1",
        "--pix-fmt",
        "yuv420p",
        "--out",
        "cyl.mkv",
    ]);
    ok(d, "omniwarp", &args);
    for (kind, field) in [
        ("v", "r_frame_rate"),
        ("a", "codec_name"),
        ("a", "sample_rate"),
    ] {
        assert_eq!(
            probe(d, "cyl.mkv", kind, field),
            probe(d, "src.mkv", kind, field),
            "{kind} {field}"
        );
    }
    let tc = |f: &str| {
        let out = Command::new("ffprobe")
            .current_dir(d)
            .args([
                "-v",
                "error",
                "-show_entries",
                "format_tags=timecode:stream_tags=timecode",
            ])
            .args(["-of", "csv=p=0", f])
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).contains("01:00:00:00")
    };
    assert!(tc("cyl.mkv"), "timecode lost");
    // The untagged source was taken as BT.601 limited, and the output says so.
    assert_eq!(probe(d, "cyl.mkv", "v", "color_space"), "smpte170m");
    assert_eq!(probe(d, "cyl.mkv", "v", "color_range"), "tv");
    let sources = frames(d, "src.mkv", "in");
    let outs = frames(d, "cyl.mkv", "out");
    assert_eq!((sources.len(), outs.len()), (12, 12));
    let mut worst = f64::INFINITY;
    for (src, out) in sources.iter().zip(&outs) {
        let mut args = vec![
            "render",
            "--content",
            src.to_str().unwrap(),
            "--content-format",
            "equirect",
        ];
        args.extend(CYLINDER);
        args.extend(["--out", "still.png"]);
        ok(d, "omniwarp", &args);
        // The still through the same 4:2:0 storage the movie went through.
        ffmpeg(d, "-i still.png -pix_fmt yuv420p -c:v ffv1 still.mkv");
        ffmpeg(d, "-i still.mkv still420.png");
        let p = psnr(
            &read_u8(out),
            &read_u8(&d.join("still420.png")),
            255.0,
            |_, _| true,
        );
        worst = worst.min(p);
    }
    println!("4:2:0 movie frames against their stills: at worst {worst:.1} dB");
    // Measured 42.2 dB: the movie is warped in Y′CbCr, its chroma replicated over each 2×2
    // block and averaged again, where the reference went through ffmpeg's own upsampling to RGB
    // and back (ffmpeg's two upsamplers differ by 27 dB on these hard colour edges). A frame off
    // by one or swapped chroma planes score below 15.
    assert!(worst > 38.0, "{worst} dB");

    let rig = root().join("calibration/rigs/cylinder-270-3proj.json");
    let rig = rig.to_str().unwrap();
    let common = [
        "render",
        "--rig",
        rig,
        "--content",
        "src.mkv",
        "--content-format",
        "equirect",
        "--encoder",
        "ffv1",
    ];
    let mut all = common.to_vec();
    all.extend(["--out", "all-{channel}.nut"]);
    ok(d, "omniwarp", &all);
    for id in ["left", "centre", "right"] {
        let mut one = common.to_vec();
        let out = format!("one-{id}.nut");
        one.extend(["--channel", id, "--out", &out]);
        ok(d, "omniwarp", &one);
        let a = frames(d, &format!("all-{id}.nut"), &format!("fa-{id}"));
        let b = frames(d, &out, &format!("fb-{id}"));
        assert_eq!(a.len(), 12, "{id}");
        for (x, y) in a.iter().zip(&b) {
            assert!(read_u8(x) == read_u8(y), "{id}: {}", x.display());
        }
    }
}

/// Bad input: each a named error, no output left behind, not even a temporary file.
#[test]
fn bad_movies_and_sequences_are_named_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "src.mkv", "yuv420p");
    ffmpeg(d, "-i src.mkv -c:v libx264 -preset ultrafast -an whole.mp4");
    let bytes = std::fs::read(d.join("whole.mp4")).unwrap();
    std::fs::write(d.join("cut.mp4"), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(d.join("noise.mp4"), vec![7u8; 5000]).unwrap();
    frames(d, "src.mkv", "seq");
    std::fs::create_dir(d.join("gap")).unwrap();
    std::fs::create_dir(d.join("sizes")).unwrap();
    for k in [1, 2, 4] {
        std::fs::copy(
            d.join(format!("seq-{k:03}.png")),
            d.join(format!("gap/f-{k:03}.png")),
        )
        .unwrap();
    }
    for k in [1, 2] {
        std::fs::copy(
            d.join(format!("seq-{k:03}.png")),
            d.join(format!("sizes/f-{k:03}.png")),
        )
        .unwrap();
    }
    ffmpeg(d, "-i seq-003.png -vf scale=128:64 sizes/f-003.png");
    let cases: [(&str, &[&str], &str); 8] = [
        ("cut.mp4", &[], "cut.mp4"),
        ("noise.mp4", &[], "noise.mp4"),
        ("gap/f-%03d.png", &[], "f-003.png"),
        ("sizes/f-%03d.png", &[], "128×64"),
        ("src.mkv", &["--frame-rate", "25"], "--frame-rate"),
        ("src.mkv", &["--encoder", "x;rm"], "--encoder"),
        ("src.mkv", &["--out", "out.gif"], "--out"),
        ("seq-%03d.png", &["--out", "seq-%03d.png"], "--out"),
    ];
    let before: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    for (content, extra, named) in cases {
        let mut args = vec![
            "render",
            "--content",
            content,
            "--content-format",
            "equirect",
        ];
        args.extend(CYLINDER);
        let out_given = extra.contains(&"--out");
        args.extend(extra);
        if !out_given {
            args.extend(["--out", "out.mkv"]);
        }
        let (success, err) = run(d, "omniwarp", &args);
        assert!(!success, "{content} {extra:?} was accepted");
        assert!(
            err.contains(named),
            "{content} {extra:?}: `{err}` does not name {named}"
        );
        assert!(!err.contains("panicked"), "{err}");
        let after: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(
            after.len(),
            before.len(),
            "{content} {extra:?} left {after:?}"
        );
    }
    // Without ffmpeg: the package to install is named.
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .current_dir(d)
        .env("OMNIWARP_FFMPEG_DIR", "/nonexistent")
        .args([
            "render",
            "--content",
            "src.mkv",
            "--content-format",
            "equirect",
        ])
        .args(CYLINDER)
        .args(["--out", "out.mkv"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("apt install ffmpeg"),
        "{err}"
    );
}

/// Ctrl-C in the middle: the run stops, its ffmpeg children with it, and neither the output nor
/// a temporary file is left; a sequence's frames written so far are removed too.
#[test]
fn ctrl_c_in_the_middle_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=1024x512:rate=30 -frames:v 900 -c:v libx264 -preset ultrafast long.mp4",
    );
    for out in ["out.mp4", "out-%05d.png"] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
            .current_dir(d)
            .args([
                "render",
                "--content",
                "long.mp4",
                "--content-format",
                "equirect",
            ])
            .args([
                "--projection",
                "cylindrical",
                "--hfov",
                "270",
                "--vfov",
                "90",
            ])
            .args(["--size", "1920x640", "--out", out])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Until the output has started to appear.
        let t = std::time::Instant::now();
        let started = || {
            std::fs::read_dir(d)
                .unwrap()
                .any(|e| e.unwrap().file_name().to_string_lossy().contains("out"))
        };
        while !started() && t.elapsed().as_secs() < 60 {
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert!(
            child.try_wait().unwrap().is_none(),
            "{out}: finished before Ctrl-C"
        );
        Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .unwrap();
        let status = child.wait().unwrap();
        let mut err = String::new();
        std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
        assert!(!status.success(), "{out}: {err}");
        assert!(err.contains("stopped"), "{out}: {err}");
        let left: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n != "long.mp4")
            .collect();
        assert!(left.is_empty(), "{out}: left {left:?}");
    }
}

/// A phone's movie tagged to be shown turned, and one carrying cover art: the frames are read
/// as stored, from the video stream, and warp as the plain movie's do. (Without
/// `-noautorotate` the turned movie's frames differ. ffmpeg's MP4 and MOV muxers put the cover
/// after the video, so the probed stream index, which keeps the cover out where it comes first,
/// is not what this case tells apart.)
#[test]
fn rotation_tags_and_cover_art_do_not_change_the_frames_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "src.mkv", "yuv420p");
    ffmpeg(
        d,
        "-i src.mkv -an -c:v libx264 -preset ultrafast -qp 0 plain.mp4",
    );
    ffmpeg(
        d,
        "-i plain.mp4 -c copy -metadata:s:v:0 rotate=90 turned.mp4",
    );
    ffmpeg(d, "-i src.mkv -frames:v 1 cover.png");
    ffmpeg(
        d,
        "-i cover.png -i plain.mp4 -map 0 -map 1:v -c:v:0 png -c:v:1 copy -disposition:v:0 attached_pic covered.mp4",
    );
    let render = |input: &str, out: &str| {
        let mut args = vec!["render", "--content", input, "--content-format", "equirect"];
        args.extend(CYLINDER);
        args.extend(["--out", out]);
        ok(d, "omniwarp", &args);
    };
    render("plain.mp4", "plain.nut");
    render("turned.mp4", "turned.nut");
    render("covered.mp4", "covered.nut");
    let a = frames(d, "plain.nut", "a");
    assert_eq!(a.len(), 12);
    for (other, prefix) in [("turned.nut", "b"), ("covered.nut", "c")] {
        let b = frames(d, other, prefix);
        assert_eq!(b.len(), 12, "{other}");
        for (x, y) in a.iter().zip(&b) {
            assert!(read_u8(x) == read_u8(y), "{other}: {}", y.display());
        }
    }
}
