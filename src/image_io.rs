//! Reading and writing images. Every write goes to a temporary file in the target's directory,
//! is flushed to disk and then renamed over the target, so a crash or a bad input never leaves a
//! half-written file behind.

use crate::error::{Error, Result};
use crate::raster::Raster;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// An image as read from disk: 8-bit formats stay 8-bit, EXR is float.
#[derive(Debug, Clone)]
pub enum Loaded {
    /// A PNG or JPEG as 8-bit RGBA, top row first.
    U8(Raster<[u8; 4]>),
    /// An OpenEXR file as float RGBA (alpha 1 where the file has none), top row first.
    F32(Raster<[f32; 4]>),
}

impl Loaded {
    /// The image's width, pixels.
    pub fn width(&self) -> usize {
        match self {
            Loaded::U8(r) => r.width,
            Loaded::F32(r) => r.width,
        }
    }

    /// The image's height, pixels.
    pub fn height(&self) -> usize {
        match self {
            Loaded::U8(r) => r.height,
            Loaded::F32(r) => r.height,
        }
    }
}

pub(crate) fn is_exr(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// Reads a PNG or JPEG (as 8-bit RGBA) or an OpenEXR file (as float RGBA; alpha 1 if absent).
pub fn read_image(path: &Path) -> Result<Loaded> {
    if is_exr(path) {
        return read_exr_rgba(path).map(|(r, _)| Loaded::F32(r));
    }
    let img = image::open(path).map_err(|e| crate::Error::file(path, e))?;
    let rgba = img.to_rgba8();
    let (w, h) = (rgba.width() as usize, rgba.height() as usize);
    let data = rgba.pixels().map(|p| p.0).collect();
    Ok(Loaded::U8(Raster {
        width: w,
        height: h,
        data,
    }))
}

/// Text attributes of an EXR header, name and value.
pub type Attributes = Vec<(String, String)>;

/// Reads a cube map stored as six images, `pattern` naming them with `{face}` (replaced by px,
/// nx, py, ny, pz, nz), and returns them side by side in face order (the `Strip` layout).
pub fn read_cube_faces(pattern: &str) -> Result<Loaded> {
    use crate::cubemap::{CubeMap, Face, Layout};
    if !pattern.contains("{face}") {
        return Err(Error::invalid(
            "content",
            format!("`{pattern}` must contain {{face}} to name six face images"),
        ));
    }
    let faces: Vec<Loaded> = Face::ALL
        .iter()
        .map(|f| read_image(Path::new(&pattern.replace("{face}", f.label()))))
        .collect::<Result<_>>()?;
    // Six rasters of one pixel type joined into a strip; a face of the other type is an error.
    fn strip<T: crate::raster::Pixel>(faces: Vec<Option<Raster<T>>>) -> Result<Raster<T>> {
        let faces: Vec<Raster<T>> = faces
            .into_iter()
            .map(|f| {
                f.ok_or_else(|| {
                    Error::invalid("content", "the six faces mix 8-bit and float images")
                })
            })
            .collect::<Result<_>>()?;
        Ok(Layout::Strip.join(&CubeMap::from_faces(faces.try_into().expect("six faces"))?))
    }
    Ok(match &faces[0] {
        Loaded::U8(_) => Loaded::U8(strip(
            faces
                .into_iter()
                .map(|l| match l {
                    Loaded::U8(r) => Some(r),
                    Loaded::F32(_) => None,
                })
                .collect(),
        )?),
        Loaded::F32(_) => Loaded::F32(strip(
            faces
                .into_iter()
                .map(|l| match l {
                    Loaded::F32(r) => Some(r),
                    Loaded::U8(_) => None,
                })
                .collect(),
        )?),
    })
}

/// Reads the first RGBA layer of an EXR file and its text attributes.
pub fn read_exr_rgba(path: &Path) -> Result<(Raster<[f32; 4]>, Attributes)> {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |res, _| Raster::<[f32; 4]>::new(res.width(), res.height()),
            |r: &mut Raster<[f32; 4]>, pos, (cr, cg, cb, ca): (f32, f32, f32, f32)| {
                let w = r.width;
                r.data[pos.y() * w + pos.x()] = [cr, cg, cb, ca];
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| crate::Error::file(path, e))?;
    let attrs = image
        .layer_data
        .attributes
        .other
        .iter()
        .filter_map(|(k, v)| match v {
            AttributeValue::Text(t) => Some((k.to_string(), t.to_string())),
            _ => None,
        })
        .collect();
    Ok((image.layer_data.channel_data.pixels, attrs))
}

/// One step of a durable write, as [`atomic_write`] takes it. Recorded (and failed on demand)
/// by [`journal`], so tests can check the order that makes a write survive power loss, which a
/// killed process cannot show: the page cache outlives the process.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// The new contents written into a temporary file beside the target.
    Write {
        /// The temporary file.
        temp: PathBuf,
        /// The bytes written into it.
        bytes: Vec<u8>,
    },
    /// The temporary file's contents made durable (fsync).
    SyncFile {
        /// The temporary file.
        temp: PathBuf,
    },
    /// The temporary file renamed over the target.
    Rename {
        /// The temporary file.
        temp: PathBuf,
        /// The target it replaces.
        to: PathBuf,
    },
    /// The directory made durable, and with it the rename (fsync of the directory).
    SyncDir {
        /// The directory holding the target (or a new directory's parent).
        dir: PathBuf,
    },
}

struct Journal {
    steps: Vec<Step>,
    fail_at: Option<usize>,
}

thread_local! {
    static JOURNAL: std::cell::RefCell<Option<Journal>> = const { std::cell::RefCell::new(None) };
}

/// Runs `f` with every [`atomic_write`] step on this thread recorded; with `fail_at = Some(k)`
/// the k-th step (from 0) fails instead of running, as a full disk or an I/O error would.
/// Returns what `f` returned and the steps taken (the failed one included).
pub fn journal<R>(fail_at: Option<usize>, f: impl FnOnce() -> R) -> (R, Vec<Step>) {
    JOURNAL.with(|j| {
        *j.borrow_mut() = Some(Journal {
            steps: Vec::new(),
            fail_at,
        })
    });
    let out = f();
    let steps = JOURNAL.with(|j| j.borrow_mut().take().map(|j| j.steps).unwrap_or_default());
    (out, steps)
}

/// Takes one step of a durable write: records it if a journal is open, fails it if it is the
/// step to fail, else runs `op`. Each step's record and its system call are the one call, so a
/// step left out of [`atomic_write`] is missing from the journal too.
fn take_step(path: &Path, s: Step, op: impl FnOnce() -> std::io::Result<()>) -> Result<()> {
    let injected = JOURNAL.with(|j| match j.borrow_mut().as_mut() {
        None => false,
        Some(j) => {
            let failed = j.fail_at == Some(j.steps.len());
            j.steps.push(s);
            failed
        }
    });
    if injected {
        return Err(Error::file(
            path,
            std::io::Error::other("injected fault (image_io::journal)"),
        ));
    }
    op().map_err(|e| Error::file(path, e))
}

/// Writes `path` atomically and durably: `write` fills a temporary file beside it, which is
/// synced, renamed over `path`, and the directory synced, so that after a crash or power loss
/// `path` holds either the old contents or the new, and the new once this returns `Ok`.
pub fn atomic_write(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> Result<()>,
) -> Result<()> {
    place(path, Access::Shared, true, write).map(drop)
}

/// Who may read a file the daemon keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Readable by everyone (0644), as a file the user asked for.
    Shared,
    /// Readable by its owner only (0600): the daemon's state says how a venue is set up.
    Private,
}

/// [`atomic_write`] with the file's [`Access`]; with `replace` false, an existing `path` is
/// left as it is and `Ok(false)` returned: the new file appears only if none was there, in
/// one step (a hard link, as `O_EXCL`), so two writers racing for one name cannot both win.
pub fn atomic_write_as(
    path: &Path,
    access: Access,
    replace: bool,
    write: impl FnOnce(&mut std::fs::File) -> Result<()>,
) -> Result<bool> {
    place(path, access, replace, write)
}

fn place(
    path: &Path,
    access: Access,
    replace: bool,
    write: impl FnOnce(&mut std::fs::File) -> Result<()>,
) -> Result<bool> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    // The temporary file is an implementation detail: a failure to create it is reported
    // against the file the caller asked for, with the operating system's reason.
    let mut tmp = tempfile::Builder::new()
        .prefix(".omniwarp-")
        .tempfile_in(dir)
        .map_err(|e| {
            // tempfile's message ends with the temporary path (" at path …"); keep the OS
            // reason and its kind.
            let text = e.to_string();
            let reason = text.split(" at path ").next().unwrap_or(&text).to_string();
            Error::file(path, std::io::Error::new(e.kind(), reason))
        })?;
    write(tmp.as_file_mut())?;
    let temp = tmp.path().to_path_buf();
    let recording = JOURNAL.with(|j| j.borrow().is_some());
    let bytes = if recording {
        std::fs::read(&temp).map_err(|e| Error::file(path, e))?
    } else {
        Vec::new()
    };
    take_step(
        path,
        Step::Write {
            temp: temp.clone(),
            bytes,
        },
        || Ok(()),
    )?;
    // Temporary files are private (0600); a shared result should be as readable as any new
    // file.
    #[cfg(unix)]
    if access == Access::Shared {
        use std::os::unix::fs::PermissionsExt;
        let perms = std::fs::Permissions::from_mode(0o644);
        tmp.as_file()
            .set_permissions(perms)
            .map_err(|e| Error::file(path, e))?;
    }
    take_step(path, Step::SyncFile { temp: temp.clone() }, || {
        tmp.as_file().sync_all()
    })?;
    let rename = Step::Rename {
        temp,
        to: path.to_path_buf(),
    };
    let mut tmp = Some(tmp);
    let mut existed = false;
    take_step(path, rename, || {
        let t = tmp.take().expect("renamed once");
        if replace {
            return t.persist(path).map(drop).map_err(|e| e.error);
        }
        match t.persist_noclobber(path) {
            Err(e) if e.error.kind() == std::io::ErrorKind::AlreadyExists => {
                existed = true;
                Ok(())
            }
            r => r.map(drop).map_err(|e| e.error),
        }
    })?;
    if existed {
        return Ok(false);
    }
    // The rename is durable only once the directory entry is; a failure here means the write
    // may not survive a crash, so it is not reported as done.
    take_step(
        path,
        Step::SyncDir {
            dir: dir.to_path_buf(),
        },
        || std::fs::File::open(dir)?.sync_all(),
    )?;
    Ok(true)
}

/// Writes an 8-bit RGBA PNG.
pub fn write_png(path: &Path, img: &Raster<[u8; 4]>) -> Result<()> {
    let bytes = png_bytes(img)?;
    atomic_write(path, |f| {
        f.write_all(&bytes).map_err(|e| Error::file(path, e))
    })
}

/// Float precision of an EXR file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// 32-bit floats: values round-trip bit-exactly.
    Float,
    /// 16-bit half floats (11 significant bits): smaller files; a warp map's vectors are then
    /// off by at most about 0.03°.
    Half,
}

/// Writes a float RGBA EXR with text attributes, losslessly compressed.
pub fn write_exr_rgba(
    path: &Path,
    img: &Raster<[f32; 4]>,
    attributes: &[(String, String)],
    precision: Precision,
) -> Result<()> {
    atomic_write(path, |f| {
        encode_exr(BufWriter::new(f), img, attributes, precision).map_err(|e| Error::file(path, e))
    })
}

/// The EXR file of [`write_exr_rgba`], in memory (for the daemon's responses).
pub fn exr_bytes(
    img: &Raster<[f32; 4]>,
    attributes: &[(String, String)],
    precision: Precision,
) -> Result<Vec<u8>> {
    let mut out = std::io::Cursor::new(Vec::new());
    encode_exr(&mut out, img, attributes, precision)
        .map_err(|e| Error::invalid("exr", e.to_string()))?;
    Ok(out.into_inner())
}

fn encode_exr(
    w: impl Write + std::io::Seek,
    img: &Raster<[f32; 4]>,
    attributes: &[(String, String)],
    precision: Precision,
) -> std::result::Result<(), exr::error::Error> {
    use exr::prelude::*;
    let mut attrs = LayerAttributes::named("rgba");
    for (k, v) in attributes {
        attrs.other.insert(
            Text::from(k.as_str()),
            AttributeValue::Text(Text::from(v.as_str())),
        );
    }
    let size = (img.width, img.height);
    let px = |p: Vec2<usize>| img.data[p.y() * img.width + p.x()];
    match precision {
        Precision::Float => {
            let ch = SpecificChannels::rgba(|p: Vec2<usize>| {
                let [r, g, b, a] = px(p);
                (r, g, b, a)
            });
            Image::from_layer(Layer::new(size, attrs, Encoding::FAST_LOSSLESS, ch))
                .write()
                .to_buffered(w)
        }
        Precision::Half => {
            let ch = SpecificChannels::rgba(|p: Vec2<usize>| {
                let [r, g, b, a] = px(p).map(f16::from_f32);
                (r, g, b, a)
            });
            Image::from_layer(Layer::new(size, attrs, Encoding::FAST_LOSSLESS, ch))
                .write()
                .to_buffered(w)
        }
    }
}

/// How hard a PNG is compressed: previews favour time (`fast` is fdeflate, several times
/// quicker than `balanced` for files a third larger), files kept on disk favour size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// `fast`: fdeflate, the quickest; the default for previews.
    Fast,
    /// `balanced`: the png crate's balance of time and size.
    Balanced,
    /// `high`: the smallest files, at much more time than `balanced`.
    High,
}

impl Compression {
    /// The level named `fast`, `balanced` or `high` (as the API's `compression` parameter
    /// spells it); any other name is an error.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "fast" => Ok(Compression::Fast),
            "balanced" => Ok(Compression::Balanced),
            "high" => Ok(Compression::High),
            other => Err(Error::invalid(
                "compression",
                format!("must be fast, balanced or high, got `{other}`"),
            )),
        }
    }
}

/// An 8-bit RGBA PNG in memory at the given compression.
pub fn png_bytes_with(img: &Raster<[u8; 4]>, compression: Compression) -> Result<Vec<u8>> {
    let err = |e: png::EncodingError| Error::invalid("png", e.to_string());
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, img.width as u32, img.height as u32);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(match compression {
            Compression::Fast => png::Compression::Fast,
            Compression::Balanced => png::Compression::Balanced,
            Compression::High => png::Compression::High,
        });
        let mut writer = enc.write_header().map_err(err)?;
        writer
            .write_image_data(img.data.as_flattened())
            .map_err(err)?;
        writer.finish().map_err(err)?;
    }
    Ok(out)
}

/// An 8-bit RGBA PNG in memory, at the `image` crate's default (fast) compression.
pub fn png_bytes(img: &Raster<[u8; 4]>) -> Result<Vec<u8>> {
    let bytes: Vec<u8> = img.data.iter().flatten().copied().collect();
    let mut out = Vec::new();
    let enc = image::codecs::png::PngEncoder::new(&mut out);
    image::ImageEncoder::write_image(
        enc,
        &bytes,
        img.width as u32,
        img.height as u32,
        image::ExtendedColorType::Rgba8,
    )
    .map_err(|e| Error::invalid("png", e.to_string()))?;
    Ok(out)
}

/// Creates `dir` (and its parents) if missing; a new directory's entry is made durable by
/// syncing its parent, so the first file written into it cannot vanish with it on power loss.
pub fn create_dir_durably(dir: &Path) -> Result<()> {
    make_dir_durably(dir, Access::Shared)
}

/// [`create_dir_durably`] for the daemon's own directories: the ones it creates are private
/// (0700); one that exists is left as it is.
pub fn create_private_dir_durably(dir: &Path) -> Result<()> {
    make_dir_durably(dir, Access::Private)
}

fn make_dir_durably(dir: &Path, access: Access) -> Result<()> {
    if dir.is_dir() {
        return Ok(());
    }
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    if access == Access::Private {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(dir).map_err(|e| Error::file(dir, e))?;
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    take_step(
        dir,
        Step::SyncDir {
            dir: parent.to_path_buf(),
        },
        || std::fs::File::open(parent)?.sync_all(),
    )
}

/// Removes the temporary files [`atomic_write`] leaves when the process is killed between
/// creating and renaming one; returns how many there were.
pub fn remove_leftovers(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".omniwarp-"))
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter(|e| std::fs::remove_file(e.path()).is_ok())
        .count()
}
