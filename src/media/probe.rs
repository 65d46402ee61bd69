//! What a movie holds, as `ffprobe` reports it: the first video stream's size, rate, frame count,
//! pixel format and colour tags, whether there is sound, and the timecode.

use super::yuv::Matrix;
use crate::{Error, Result};
use serde_json::Value;
use std::path::Path;

/// A frame rate as a fraction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rate {
    /// Frames per `den` seconds.
    pub num: u32,
    /// Seconds per `num` frames.
    pub den: u32,
}

impl Rate {
    /// Frames per second.
    pub fn fps(self) -> f64 {
        f64::from(self.num) / f64::from(self.den)
    }

    /// `num/den`, as ffmpeg takes it.
    pub fn text(self) -> String {
        format!("{}/{}", self.num, self.den)
    }

    /// Parses `30000/1001`, `25` or `29.97` (at most 1000 frames a second).
    pub fn parse(text: &str) -> Option<Rate> {
        let (num, den) = match text.split_once('/') {
            Some((n, d)) => (n.trim().parse().ok()?, d.trim().parse().ok()?),
            None => {
                let f: f64 = text.trim().parse().ok()?;
                ((f * 1000.0).round() as u32, 1000)
            }
        };
        (num > 0 && den > 0 && u64::from(num) <= 1000 * u64::from(den)).then_some(Rate { num, den })
    }
}

/// A movie's first video stream and what travels with it.
#[derive(Debug, Clone, PartialEq)]
pub struct Info {
    /// Frame width and height, pixels.
    pub size: (usize, usize),
    /// Frame rate.
    pub rate: Rate,
    /// Frame count, when the container says or the duration gives it.
    pub frames: Option<u64>,
    /// ffmpeg's name of the stored pixel format (`yuv420p`, `rgb24`, …).
    pub pix_fmt: String,
    /// Whether the movie has a sound stream (copied to the outputs).
    pub audio: bool,
    /// The start timecode, when tagged.
    pub timecode: Option<String>,
    /// Colour tags as ffmpeg names them: matrix, primaries, transfer, range.
    pub color: [Option<String>; 4],
    /// The video stream's index in the file (cover art, an attached picture, is skipped).
    pub stream: u64,
}

impl Info {
    /// Asks `ffprobe` about the movie at `path`; a named error if it is not one ffmpeg reads.
    pub fn probe(path: &Path) -> Result<Info> {
        let out = super::command("ffprobe")
            .args([
                "-v",
                "error",
                "-print_format",
                "json",
                "-show_streams",
                "-show_format",
            ])
            .arg(path)
            .output()
            .map_err(|e| super::not_started("ffprobe", e))?;
        if !out.status.success() {
            return Err(Error::file(
                path,
                format!("ffprobe cannot read it: {}", super::tail(&out.stderr)),
            ));
        }
        let v: Value = serde_json::from_slice(&out.stdout)
            .map_err(|e| Error::file(path, format!("ffprobe's answer: {e}")))?;
        Self::from_json(&v).map_err(|reason| Error::file(path, reason))
    }

    fn from_json(v: &Value) -> std::result::Result<Info, String> {
        let streams = v["streams"].as_array().cloned().unwrap_or_default();
        let kind = |s: &Value, k: &str| s["codec_type"].as_str() == Some(k);
        let video = streams
            .iter()
            .find(|s| kind(s, "video") && s["disposition"]["attached_pic"].as_i64() != Some(1))
            .ok_or("it has no video stream")?;
        let text = |s: &Value, k: &str| s[k].as_str().map(str::to_string);
        let dim = |k: &str| {
            video[k]
                .as_u64()
                .filter(|&d| (2..=crate::limits::MEDIA_SIDE).contains(&d))
                .map(|d| d as usize)
                .ok_or(format!(
                    "its {k} must be 2–{} pixels, got {}",
                    crate::limits::MEDIA_SIDE,
                    video[k]
                ))
        };
        let size = (dim("width")?, dim("height")?);
        let rate = ["r_frame_rate", "avg_frame_rate"]
            .iter()
            .find_map(|k| video[*k].as_str().and_then(Rate::parse))
            .ok_or("it states no frame rate")?;
        let duration = text(video, "duration")
            .or_else(|| text(&v["format"], "duration"))
            .and_then(|d| d.parse::<f64>().ok());
        let frames = text(video, "nb_frames")
            .and_then(|n| n.parse::<u64>().ok())
            .filter(|&n| n > 0)
            .or_else(|| duration.map(|d| (d * rate.fps()).round() as u64));
        let pix_fmt = text(video, "pix_fmt").ok_or("it states no pixel format")?;
        // Matroska spells the tag TIMECODE, MP4 and MOV timecode.
        let timecode = [&video["tags"], &v["format"]["tags"]]
            .iter()
            .find_map(|tags| {
                tags.as_object()?
                    .iter()
                    .find(|(k, _)| k.eq_ignore_ascii_case("timecode"))
                    .and_then(|(_, t)| t.as_str().map(str::to_string))
            });
        let tag = |k: &str| text(video, k).filter(|t| t != "unknown" && t != "reserved");
        Ok(Info {
            stream: video["index"].as_u64().unwrap_or(0),
            size,
            rate,
            frames,
            pix_fmt,
            audio: streams.iter().any(|s| kind(s, "audio")),
            timecode,
            color: [
                tag("color_space"),
                tag("color_primaries"),
                tag("color_transfer"),
                tag("color_range"),
            ],
        })
    }

    /// The Y′CbCr matrix the movie's tags call for.
    pub fn matrix(&self) -> Matrix {
        let range = if self.pix_fmt.starts_with("yuvj") {
            Some("pc")
        } else {
            self.color[3].as_deref()
        };
        Matrix::from_tags(self.color[0].as_deref(), range)
    }

    /// Whether samples have more than 8 bits (10-bit Y′CbCr, 16-bit RGB, float).
    pub fn deep(&self) -> bool {
        let f = &self.pix_fmt;
        ["10", "12", "14", "16", "f32", "f16", "48", "64"]
            .iter()
            .any(|d| f.contains(d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_ffprobes_answer_and_names_what_is_missing() {
        let v: Value = serde_json::from_str(
            r#"{"streams":[{"codec_type":"video","width":640,"height":360,"pix_fmt":"yuv420p",
            "r_frame_rate":"30000/1001","nb_frames":"60","color_space":"bt709",
            "color_range":"tv","tags":{"timecode":"01:00:00;00"}},{"codec_type":"audio"}],
            "format":{"duration":"2.002"}}"#,
        )
        .unwrap();
        let i = Info::from_json(&v).unwrap();
        assert_eq!(i.size, (640, 360));
        assert_eq!(
            i.rate,
            Rate {
                num: 30000,
                den: 1001
            }
        );
        assert_eq!(i.frames, Some(60));
        assert!(i.audio && !i.deep());
        assert_eq!(i.timecode.as_deref(), Some("01:00:00;00"));
        assert_eq!(i.matrix(), Matrix::from_tags(Some("bt709"), None));
        let none: Value = serde_json::from_str(r#"{"streams":[{"codec_type":"audio"}]}"#).unwrap();
        assert!(Info::from_json(&none).unwrap_err().contains("no video"));
        assert_eq!(
            Rate::parse("25"),
            Some(Rate {
                num: 25000,
                den: 1000
            })
        );
        assert_eq!(Rate::parse("0/1"), None);
        assert_eq!(Rate::parse("5000"), None);
    }
}
