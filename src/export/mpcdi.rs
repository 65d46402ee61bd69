//! MPCDI packages (VESA): a ZIP with `mpcdi.xml` and, per region, a warp PFM and an alpha PNG,
//! every member at the root.
//!
//! In the 2d (media) profile the buffer is the content canvas the media server plays, at its
//! pixel size, and each region is the sub-rectangle of it that one projector shows (the
//! bounding box of what it shows, padded, clamped to the canvas); the warp's coordinates are
//! relative to the region. That is how readers sample it: PyMPCDI looks the media up at
//! `x + u·xsize`, nDisplay cuts the region out of the input image. In the a3 profile, which
//! has no content canvas, the buffer is the projectors side by side, one region each.
//!
//! Readers disagree on the vertical direction, the PFM's row order and where the grid's nodes
//! lie; [`Reader`] names each reader's conventions (docs/mpcdi.md cites the sources).
//!
//! The spelling follows the reference reader (tinyxml2, case-sensitive), not the spec's:
//! `Xresolution`, `Yresolution`, `xsize`, `ysize`, `originof3DData`, and `level` is written in
//! v2.0 files too. The reader here accepts any letter case.

use super::grid::{Cells, Layout, Reading, Shape};
use crate::error::{Error, Result};
use std::io::{Cursor, Read, Write};

/// A package's MPCDI profile: what its warp samples hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Profile {
    /// Normalised content (x, y) per sample (top-left origin), B = NaN (no error estimate).
    TwoD,
    /// Wall X, Y, Z per sample, metres, origin at the ideal eye point.
    A3,
}

impl Profile {
    /// The name written in the root's `profile` attribute and taken by the daemon's `profile=`:
    /// `2d` or `a3`.
    pub fn name(self) -> &'static str {
        match self {
            Profile::TwoD => "2d",
            Profile::A3 => "a3",
        }
    }
}

/// The MPCDI version a package is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Version {
    /// MPCDI v1.0 (`version="1.0"`): what WATCHOUT reads.
    V1,
    /// MPCDI v2.0 (`version="2.0"`, with `geometry="1"` and `color="1"`): the default for every
    /// other reader.
    V2,
}

impl Version {
    /// The version spelled `1.0` or `2.0` (`--mpcdi-version`, the daemon's `version=`); an
    /// error naming `field` otherwise.
    pub fn parse(s: &str, field: &str) -> Result<Self> {
        match s {
            "1.0" => Ok(Version::V1),
            "2.0" => Ok(Version::V2),
            other => Err(Error::invalid(
                field,
                format!("must be 1.0 or 2.0, got `{other}`"),
            )),
        }
    }
}

/// The reader a 2d package is written for: readers disagree on three conventions, and a
/// package can only follow one set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reader {
    /// The VESA/Scalable reference library and what is built on it: region y and v measured
    /// down from the top (the spec's "first pixel top-left"), PFM rows bottom to top on disk
    /// as netpbm says (the library reads them back top-first), nodes edge to edge.
    Vesa,
    /// Unreal nDisplay: parses with the VESA library, builds its mesh with UV = i / (n − 1).
    Ndisplay,
    /// WATCHOUT: the VESA conventions (its importer's conventions are not published); reads
    /// MPCDI v1.0.
    Watchout,
    /// drwrose/PyMPCDI: region y and v measured up from the bottom (OpenGL's t), the PFM's
    /// first row on disk drawn at the top, the grid sampled as a texture (nodes at cell
    /// centres).
    Pympcdi,
    /// SGCT's PFM correction mesh (its MPCDI reader was removed in 2024): v up as OpenGL's t,
    /// the first row on disk at the top, nodes edge to edge.
    Sgct,
}

impl Reader {
    /// Every reader, in the order error messages list them.
    pub const ALL: [Reader; 5] = [
        Reader::Vesa,
        Reader::Ndisplay,
        Reader::Watchout,
        Reader::Pympcdi,
        Reader::Sgct,
    ];

    /// The reader's name as `--reader` and the daemon's `reader=` spell it: `vesa`,
    /// `ndisplay`, `watchout`, `pympcdi` or `sgct`.
    pub fn name(self) -> &'static str {
        match self {
            Reader::Vesa => "vesa",
            Reader::Ndisplay => "ndisplay",
            Reader::Watchout => "watchout",
            Reader::Pympcdi => "pympcdi",
            Reader::Sgct => "sgct",
        }
    }

    /// The reader named `s` (see [`Reader::name`]); an error naming `field` otherwise.
    pub fn parse(s: &str, field: &str) -> Result<Self> {
        Reader::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| {
                Error::invalid(
                    field,
                    format!("must be vesa, ndisplay, watchout, pympcdi or sgct, got `{s}`"),
                )
            })
    }

    /// Region y and v measured up from the bottom of the buffer and region.
    pub fn v_up(self) -> bool {
        matches!(self, Reader::Pympcdi | Reader::Sgct)
    }

    /// The PFM's first row on disk is the image's top row (netpbm says bottom).
    pub fn pfm_top_first(self) -> bool {
        matches!(self, Reader::Pympcdi | Reader::Sgct)
    }

    /// Where the reader places nodes and how it fills a cell. The VESA text says `linear`;
    /// PyMPCDI samples a texture; nDisplay and SGCT build triangle meshes (SGCT's strips
    /// alternate the diagonal row by row, nDisplay's is not documented) and WATCHOUT's reading is
    /// not published: for those the grid holds its tolerance however a cell is split.
    pub fn reading(self) -> Reading {
        match self {
            Reader::Vesa => Reading::BILINEAR,
            Reader::Pympcdi => Reading {
                layout: Layout::Centres,
                cells: Cells::Bilinear,
                shape: Shape::Free,
            },
            Reader::Ndisplay | Reader::Watchout | Reader::Sgct => Reading {
                layout: Layout::Edges,
                cells: Cells::Any,
                shape: Shape::Free,
            },
        }
    }

    /// The MPCDI version this reader takes when none is asked for.
    pub fn version(self) -> Version {
        match self {
            Reader::Watchout => Version::V1,
            _ => Version::V2,
        }
    }
}

/// One projector's region as written.
#[derive(Debug, Clone)]
pub struct Region {
    /// The region's id, the channel's: it also names the region's files
    /// (`GeometryWarpFile-{id}.pfm`, `AlphaMap-{id}.png`).
    pub id: String,
    /// The projector's width and height, pixels (`Xresolution`, `Yresolution`).
    pub resolution: [u32; 2],
    /// Index of its buffer in [`Header::buffers`].
    pub buffer: usize,
    /// x, y, xsize, ysize as written, normalised to the buffer.
    pub rect: [f64; 4],
    /// Warp grid size and samples, rows top to bottom (NaN where unknown).
    pub warp: (usize, usize, Vec<[f32; 3]>),
    /// Grey alpha map at the projector resolution, gamma 2.2 embedded.
    pub alpha_png: Vec<u8>,
    /// Grey beta map (black lift) at the projector resolution, in signal space as the alpha
    /// map, of the same bits; only when the rig's projectors have a contrast.
    pub beta_png: Option<Vec<u8>>,
    /// Its bits a sample: 8 by default (the VESA reference library and PyMPCDI decode 8 bits
    /// only and garble 16), 16 on request.
    pub alpha_bits: u8,
}

/// The alpha maps' bits a sample when none is asked for.
pub const ALPHA_BITS: u8 = 8;

/// Gamma baked into the alpha maps we write.
pub const ALPHA_GAMMA: f64 = 2.2;

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('"', "&quot;")
        .replace('>', "&gt;")
}

/// Seconds since the Unix epoch, for a package's date (0 if the clock is before it).
pub fn unix_now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// `yyyy-MM-dd HH:mm:ss` (UTC) of a Unix time.
fn date(unix: u64) -> String {
    let (days, secs) = ((unix / 86400) as i64, unix % 86400);
    // Howard Hinnant's civil-from-days.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// What a package says beside its regions.
#[derive(Debug, Clone)]
pub struct Header {
    /// The MPCDI version the package is written in.
    pub version: Version,
    /// The package's profile: content coordinates (2d) or wall points (a3).
    pub profile: Profile,
    /// Whose conventions the 2d warps follow (a3 warps are wall points, read alike by all).
    pub reader: Reader,
    /// The buffers' pixel sizes: one per content canvas the channels play (2d) or the
    /// projectors side by side (a3, see [`side_by_side`]).
    pub buffers: Vec<[u32; 2]>,
    /// When the package was made, seconds since the Unix epoch; written as the root's `date`
    /// (`yyyy-MM-dd HH:mm:ss`, UTC).
    pub unix_time: u64,
}

/// Places regions side by side in one buffer, top-aligned (the a3 layout: a 3D profile's buffer
/// is what the image generator outputs); returns the buffers.
pub fn side_by_side(regions: &mut [Region]) -> Vec<[u32; 2]> {
    let total_w: u32 = regions.iter().map(|r| r.resolution[0]).sum();
    let max_h = regions.iter().map(|r| r.resolution[1]).max().unwrap_or(0);
    let mut left = 0u32;
    for r in regions {
        let [w, h] = r.resolution;
        r.buffer = 0;
        r.rect = [
            f64::from(left) / f64::from(total_w),
            0.0,
            f64::from(w) / f64::from(total_w),
            f64::from(h) / f64::from(max_h),
        ];
        left += w;
    }
    vec![[total_w, max_h]]
}

/// The `mpcdi.xml` of a package.
pub fn xml(h: &Header, regions: &[Region]) -> String {
    // Beta maps are a level 2 feature: a package with them says so, so that a reader which
    // checks levels knows to read them.
    let level = if regions.iter().any(|r| r.beta_png.is_some()) {
        2
    } else {
        1
    };
    let root = match h.version {
        Version::V1 => format!(
            r#"<MPCDI profile="{}" level="{level}" date="{}" version="1.0">"#,
            h.profile.name(),
            date(h.unix_time)
        ),
        Version::V2 => format!(
            r#"<MPCDI profile="{}" geometry="1" color="{level}" level="{level}" date="{}" version="2.0">"#,
            h.profile.name(),
            date(h.unix_time)
        ),
    };
    // A 2d warp holds content coordinates, not lengths from a point: the VESA library writes
    // `unknown` for both there.
    let (unit, origin) = match h.profile {
        Profile::TwoD => ("unknown", "unknown"),
        Profile::A3 => ("m", "idealEyePoint"),
    };
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    x += &root;
    x += "\n  <display>\n";
    for (b, [bw, bh]) in h.buffers.iter().enumerate() {
        x += &format!("    <buffer id=\"buffer{b}\" Xresolution=\"{bw}\" Yresolution=\"{bh}\">\n");
        for r in regions.iter().filter(|r| r.buffer == b) {
            let [w, h] = r.resolution;
            let [rx, ry, rw, rh] = r.rect;
            x += &format!(
                "      <region id=\"{}\" x=\"{rx:.9}\" y=\"{ry:.9}\" xsize=\"{rw:.9}\" ysize=\"{rh:.9}\" Xresolution=\"{w}\" Yresolution=\"{h}\"/>\n",
                escape(&r.id),
            );
        }
        x += "    </buffer>\n";
    }
    x += "  </display>\n  <files>\n";
    for r in regions {
        let (id, bits) = (escape(&r.id), r.alpha_bits);
        x += &format!(
            "    <fileset region=\"{id}\">\n      <geometryWarpFile>\n        <path>GeometryWarpFile-{id}.pfm</path>\n        <interpolation>linear</interpolation>\n        <geometricUnit>{unit}</geometricUnit>\n        <originof3DData>{origin}</originof3DData>\n      </geometryWarpFile>\n      <alphaMap>\n        <path>AlphaMap-{id}.png</path>\n        <componentDepth>1</componentDepth>\n        <bitDepth>{bits}</bitDepth>\n        <gammaEmbedded>{ALPHA_GAMMA}</gammaEmbedded>\n      </alphaMap>\n"
        );
        if r.beta_png.is_some() {
            x += &format!(
                "      <betaMap>\n        <path>BetaMap-{id}.png</path>\n        <componentDepth>1</componentDepth>\n        <bitDepth>{bits}</bitDepth>\n      </betaMap>\n"
            );
        }
        x += "    </fileset>\n";
    }
    x += "  </files>\n</MPCDI>\n";
    x
}

/// The package's bytes.
pub fn package(h: &Header, regions: &[Region]) -> Result<Vec<u8>> {
    let zip_err = |e: zip::result::ZipError| Error::invalid("mpcdi", e.to_string());
    let io_err = |e: std::io::Error| Error::invalid("mpcdi", e.to_string());
    let mut z = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    z.start_file("mpcdi.xml", opts).map_err(zip_err)?;
    z.write_all(xml(h, regions).as_bytes()).map_err(io_err)?;
    let top_first = h.profile == Profile::TwoD && h.reader.pfm_top_first();
    for r in regions {
        let (gw, gh, samples) = &r.warp;
        // pfm_bytes writes netpbm's bottom-up order; rows handed over upside down come out
        // top row first.
        let flipped;
        let rows = if top_first && *gw > 0 {
            flipped = samples
                .chunks(*gw)
                .rev()
                .flatten()
                .copied()
                .collect::<Vec<_>>();
            &flipped
        } else {
            samples
        };
        z.start_file(format!("GeometryWarpFile-{}.pfm", r.id), opts)
            .map_err(zip_err)?;
        z.write_all(&super::pfm_bytes(*gw, *gh, rows)?)
            .map_err(io_err)?;
        z.start_file(format!("AlphaMap-{}.png", r.id), opts)
            .map_err(zip_err)?;
        z.write_all(&r.alpha_png).map_err(io_err)?;
        if let Some(beta) = &r.beta_png {
            z.start_file(format!("BetaMap-{}.png", r.id), opts)
                .map_err(zip_err)?;
            z.write_all(beta).map_err(io_err)?;
        }
    }
    Ok(z.finish().map_err(zip_err)?.into_inner())
}

/// A package as read back.
#[derive(Debug, Clone)]
pub struct Package {
    /// The root element's attributes as written (any case), e.g. `version`, `profile`, `level`.
    pub root: Vec<(String, String)>,
    /// The text of `mpcdi.xml`.
    pub xml: String,
    /// The buffers of every `<display>`, in document order.
    pub buffers: Vec<BufferRead>,
}

/// A buffer of a package as read back.
#[derive(Debug, Clone)]
pub struct BufferRead {
    /// The buffer's `id` attribute (empty if it has none), e.g. `buffer0`.
    pub id: String,
    /// The buffer's `Xresolution` and `Yresolution`, pixels.
    pub resolution: [u32; 2],
    /// The buffer's regions, in document order.
    pub regions: Vec<RegionRead>,
}

/// A region of a package as read back, with its fileset's warp and alpha map.
#[derive(Debug, Clone)]
pub struct RegionRead {
    /// The region's `id` attribute, which its fileset's `region` matches.
    pub id: String,
    /// x, y, xsize, ysize, normalised to the buffer.
    pub rect: [f64; 4],
    /// The region's `Xresolution` and `Yresolution`: the projector's size, pixels.
    pub resolution: [u32; 2],
    /// The warp file's `<interpolation>` text (`linear` as written here); empty if absent.
    pub interpolation: String,
    /// The warp file's `<geometricUnit>` text (`m` for a3, `unknown` for 2d); empty if absent.
    pub geometric_unit: String,
    /// The warp file's `<originOf3DData>` text (`idealEyePoint` for a3, `unknown` for 2d);
    /// empty if absent.
    pub origin_of_3d_data: String,
    /// The warp PFM: columns, rows and samples, rows top to bottom as netpbm orders them (a
    /// package written for a top-first reader comes back upside down).
    pub warp: (usize, usize, Vec<[f32; 3]>),
    /// Alpha in 0–1 as stored (gamma embedded), row-major.
    pub alpha: (u32, u32, Vec<f64>),
    /// The alpha map's `<gammaEmbedded>`; 1 if absent or not a number.
    pub gamma_embedded: f64,
    /// The beta map (black lift) in 0–1 as stored, row-major, if the fileset has one.
    pub beta: Option<(u32, u32, Vec<f64>)>,
}

impl Package {
    /// The value of the root element's attribute `name`, in any letter case.
    pub fn attr(&self, name: &str) -> Option<&str> {
        self.root
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

fn attr<'a>(n: roxmltree::Node<'a, '_>, name: &str) -> Option<&'a str> {
    n.attributes()
        .find(|a| a.name().eq_ignore_ascii_case(name))
        .map(|a| a.value())
}

fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    n.children()
        .find(|c| c.is_element() && c.tag_name().name().eq_ignore_ascii_case(name))
}

fn children<'a, 'i>(
    n: roxmltree::Node<'a, 'i>,
    name: &'static str,
) -> impl Iterator<Item = roxmltree::Node<'a, 'i>> {
    n.children()
        .filter(move |c| c.is_element() && c.tag_name().name().eq_ignore_ascii_case(name))
}

/// Reads a package, accepting any spelling case of the names.
pub fn read(bytes: &[u8]) -> Result<Package> {
    let bad = |why: String| Error::invalid("mpcdi", why);
    let mut z = zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| bad(e.to_string()))?;
    let mut member = |name: &str| -> Result<Vec<u8>> {
        let mut f = z
            .by_name(name)
            .map_err(|e| bad(format!("member `{name}`: {e}")))?;
        // A member's size comes from the archive: read no more than the export limit, so a
        // small package cannot inflate into gigabytes.
        let limit = crate::limits::EXPORT_BYTES as u64;
        let mut out = Vec::new();
        (&mut f)
            .take(limit + 1)
            .read_to_end(&mut out)
            .map_err(|e| bad(format!("member `{name}`: {e}")))?;
        if out.len() as u64 > limit {
            return Err(bad(format!("member `{name}` is above {limit} bytes")));
        }
        Ok(out)
    };
    let xml = String::from_utf8(member("mpcdi.xml")?)
        .map_err(|_| bad("mpcdi.xml is not UTF-8".into()))?;
    let doc = roxmltree::Document::parse(&xml).map_err(|e| bad(format!("mpcdi.xml: {e}")))?;
    let root = doc.root_element();
    if !root.tag_name().name().eq_ignore_ascii_case("MPCDI") {
        return Err(bad("the root element is not MPCDI".into()));
    }
    let num = |n: roxmltree::Node, name: &str| -> Result<f64> {
        attr(n, name)
            .and_then(|v| v.trim().parse().ok())
            .ok_or_else(|| {
                bad(format!(
                    "<{}> lacks a numeric `{name}`",
                    n.tag_name().name()
                ))
            })
    };
    let text = |n: roxmltree::Node, name: &str| -> String {
        child(n, name)
            .and_then(|c| c.text())
            .map(|t| t.trim().to_string())
            .unwrap_or_default()
    };
    let files = child(root, "files").ok_or_else(|| bad("no <files>".into()))?;
    let mut buffers = Vec::new();
    for display in children(root, "display") {
        for b in children(display, "buffer") {
            let mut regions = Vec::new();
            for r in children(b, "region") {
                let id = attr(r, "id")
                    .ok_or_else(|| bad("a region without an id".into()))?
                    .to_string();
                let fileset = children(files, "fileset")
                    .find(|f| attr(*f, "region") == Some(id.as_str()))
                    .ok_or_else(|| bad(format!("no fileset for region `{id}`")))?;
                let warp_node = child(fileset, "geometryWarpFile")
                    .ok_or_else(|| bad(format!("region `{id}`: no geometryWarpFile")))?;
                let warp_path = text(warp_node, "path");
                let warp = super::parse_pfm(&member(&warp_path)?, &warp_path)?;
                let alpha_node = child(fileset, "alphaMap")
                    .ok_or_else(|| bad(format!("region `{id}`: no alphaMap")))?;
                let alpha_path = text(alpha_node, "path");
                let mut grey = |path: &str| -> Result<(u32, u32, Vec<f64>)> {
                    let img = image::load_from_memory(&member(path)?)
                        .map_err(|e| bad(format!("{path}: {e}")))?
                        .into_luma16();
                    Ok((
                        img.width(),
                        img.height(),
                        img.pixels().map(|p| f64::from(p.0[0]) / 65535.0).collect(),
                    ))
                };
                let alpha = grey(&alpha_path)?;
                let beta = match child(fileset, "betaMap") {
                    Some(n) => Some(grey(&text(n, "path"))?),
                    None => None,
                };
                regions.push(RegionRead {
                    rect: [
                        num(r, "x")?,
                        num(r, "y")?,
                        num(r, "xsize")?,
                        num(r, "ysize")?,
                    ],
                    resolution: [num(r, "xresolution")? as u32, num(r, "yresolution")? as u32],
                    interpolation: text(warp_node, "interpolation"),
                    geometric_unit: text(warp_node, "geometricUnit"),
                    origin_of_3d_data: text(warp_node, "originOf3DData"),
                    gamma_embedded: text(alpha_node, "gammaEmbedded").parse().unwrap_or(1.0),
                    warp,
                    alpha,
                    beta,
                    id,
                });
            }
            buffers.push(BufferRead {
                id: attr(b, "id").unwrap_or_default().to_string(),
                resolution: [num(b, "xresolution")? as u32, num(b, "yresolution")? as u32],
                regions,
            });
        }
    }
    Ok(Package {
        root: root
            .attributes()
            .map(|a| (a.name().to_string(), a.value().to_string()))
            .collect(),
        xml: xml.clone(),
        buffers,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn dates_are_civil() {
        assert_eq!(super::date(0), "1970-01-01 00:00:00");
        assert_eq!(super::date(951_782_400), "2000-02-29 00:00:00");
        assert_eq!(super::date(1_795_312_861), "2026-11-22 02:01:01");
    }
}
