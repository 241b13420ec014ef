//! The outputs: EXR (f32 linear sRGB), PNG preview, JSON sidecar. Files
//! are written to a temporary name, flushed to disk and renamed, so a failed
//! or killed render never leaves a half-written file and never clobbers an
//! existing one.

use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Fails early (before any rendering) if `path` cannot be written: its
/// directory must exist and take the very temporary file `Outputs` will
/// write (whose name is longer than `path`'s: a name near the file
/// system's limit fails here, not after the render).
pub fn check_writable(path: &Path) -> Result<()> {
    let dir = parent_dir(path);
    if !dir.is_dir() {
        bail!("cannot write {}: directory {} does not exist", path.display(), dir.display());
    }
    let probe = temporary_path(path)?;
    let probe_name = probe.file_name().unwrap_or_default().len();
    if probe_name > NAME_MAX {
        bail!(
            "cannot write {}: its name is too long (the temporary file written beside it first would have a name \
             of {probe_name} bytes, over the {NAME_MAX} that file systems allow)",
            path.display()
        );
    }
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write {}: directory is not writable", path.display()))?;
    let _ = std::fs::remove_file(probe);
    if path.is_dir() {
        bail!("cannot write {}: it is a directory", path.display());
    }
    Ok(())
}

/// The longest file name (bytes) of Linux's file systems, and most others.
const NAME_MAX: usize = 255;

/// Where `Outputs` writes `path`'s new contents before moving them into
/// place: a hidden file beside it, named after it and this process.
fn temporary_path(path: &Path) -> Result<PathBuf> {
    let name = path.file_name().context("output path has no file name")?.to_string_lossy();
    let ext = path.extension().map(|e| e.to_string_lossy().to_string()).unwrap_or_default();
    Ok(parent_dir(path).join(format!(".{name}.{}.tmp.{ext}", std::process::id())))
}

/// Refuses to write a sidecar over an existing JSON file that is not a
/// sidecar (one with `scene`, `integrator` and `spp`): `prism render a.json
/// --out b.exr`, or `prism merge b.exr ...`, would replace a scene `b.json`.
pub fn check_sidecar_target(path: &Path) -> Result<()> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(()); // none (or unreadable, which `check_writable` reports)
    };
    let json: Option<serde_json::Value> = serde_json::from_str(&text).ok();
    let is_sidecar = json.is_some_and(|v| ["scene", "integrator", "spp"].iter().all(|k| v.get(k).is_some()));
    if !is_sidecar {
        bail!(
            "the sidecar {} would replace a JSON file that is not a prism sidecar (a scene?): choose another \
             output name",
            path.display()
        );
    }
    Ok(())
}

/// Refuses to write the image `out` beside an existing `out.state` (the
/// sums of a part or a merge, which `prism merge` reads in place of the
/// image): the new image would stand beside a stale state. `how` names the
/// command's other ways out.
pub fn check_no_stale_state(out: &Path, how: &str) -> Result<()> {
    let state = out.with_extension("state");
    if state.exists() {
        bail!(
            "{} holds the samples of a part or a merge, and this command would leave it stale beside the new {} \
             for `prism merge`: remove it, choose another output{how}",
            state.display(),
            out.display()
        );
    }
    Ok(())
}

/// Fails unless `path` names an .exr file: `flag` is the option that gave it.
pub fn ensure_exr(flag: &str, path: &Path) -> Result<()> {
    ensure_extension(flag, path, "exr")
}

/// Refuses an output path without the extension `ext`: a slip of `--png`
/// would otherwise write a PNG over, say, a scene's OBJ mesh.
pub fn ensure_extension(flag: &str, path: &Path, ext: &str) -> Result<()> {
    if !path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case(ext)) {
        let article = if ext.starts_with(['a', 'e', 'i', 'o', 'u']) { "an" } else { "a" };
        bail!("{flag} must name {article} .{ext} file, got {}", path.display());
    }
    Ok(())
}

/// A path with its directory resolved (and the file, if it exists), so
/// that `./s.json`, `dir/../s.json` and an absolute spelling compare equal.
pub fn resolve_path(p: &Path) -> PathBuf {
    if let Ok(c) = std::fs::canonicalize(p) {
        return c;
    }
    let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let dir = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    dir.join(p.file_name().unwrap_or_default())
}

/// Refuses outputs that would replace an input or one another: `prism render
/// s.json --out s.exr` would write its sidecar, s.json, over the scene.
/// Files are named by their role ("the scene", "--png") and compared after
/// resolving their directories (and the file, if it exists), so `./s.json`
/// and `dir/../s.json` are the same file.
pub fn check_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    let inputs: Vec<_> = inputs.iter().map(|&(role, p)| (resolve_path(p), role, p)).collect();
    let mut written: Vec<(PathBuf, &str, &Path)> = Vec::new();
    for &(role, out) in outputs {
        let key = resolve_path(out);
        if let Some((_, input, p)) = inputs.iter().find(|(k, ..)| *k == key) {
            bail!("{role} {} would replace {input} {}: choose another output name", out.display(), p.display());
        }
        if let Some((_, other, p)) = written.iter().find(|(k, ..)| *k == key) {
            bail!("{role} {} and {other} {} are the same file", out.display(), p.display());
        }
        written.push((key, role, out));
    }
    Ok(())
}

/// Output files written together: each to a temporary file beside its
/// target, flushed to disk, and all moved into place by `commit` in the
/// order they were staged, then their directories flushed. If writing any of
/// them fails, no target has changed (the temporaries are removed, also when
/// the set is dropped uncommitted); whenever the process dies, each target
/// holds either its old or its complete new contents (what checkpoints rely
/// on).
#[derive(Default)]
pub struct Outputs {
    /// (temporary, target), in staging order.
    staged: Vec<(PathBuf, PathBuf)>,
}

impl Outputs {
    /// Writes `path`'s new contents through `write` to its temporary file.
    pub fn stage(&mut self, path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
        let tmp = temporary_path(path)?;
        if self.staged.iter().any(|(_, target)| target == path) {
            bail!("{} would be written twice, as two of this run's outputs", path.display());
        }
        // Listed first, so that a failed write's partial file is removed too.
        self.staged.push((tmp.clone(), path.to_path_buf()));
        write(&tmp)?;
        sync(&tmp).with_context(|| format!("cannot flush {}", tmp.display()))
    }

    /// An f32 RGB EXR (linear sRGB).
    pub fn exr(&mut self, path: &Path, width: u32, height: u32, image: &[[f32; 3]]) -> Result<()> {
        use exr::prelude::*;
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
            let p = image[y * width as usize + x];
            (p[0], p[1], p[2])
        });
        // The default's line order is "unspecified": the crate then writes its
        // parallel-compressed blocks as they finish, so two writes of one image
        // could differ in bytes. In increasing order it sorts them, and the file
        // depends on the pixels alone.
        let encoding = Encoding { line_order: LineOrder::Increasing, ..Encoding::FAST_LOSSLESS };
        let exr = Image::from_encoded_channels((width as usize, height as usize), encoding, channels);
        // (Its message only: the exr error repeats its source's in Display.)
        self.stage(path, |tmp| {
            exr.write().to_file(tmp).map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
        })
    }

    /// An 8-bit sRGB PNG preview: linear values times 2^exposure, sRGB
    /// transfer curve, clamped. Encoded in memory, so that a failed write
    /// is reported (the image crate's file writer drops its last flush's
    /// error, and left an empty file on a full disk).
    pub fn png(&mut self, path: &Path, width: u32, height: u32, image: &[[f32; 3]], exposure: f32) -> Result<()> {
        let scale = 2f32.powf(exposure);
        let mut buf = image::RgbImage::new(width, height);
        for (i, p) in image.iter().enumerate() {
            let px = p.map(|c| srgb8(c * scale));
            buf.put_pixel(i as u32 % width, i as u32 / width, image::Rgb(px));
        }
        self.bytes(path, &encode_png(&image::DynamicImage::ImageRgb8(buf))?)
    }

    /// A JSON document.
    pub fn json<T: Serialize>(&mut self, path: &Path, value: &T) -> Result<()> {
        self.bytes(path, (serde_json::to_string_pretty(value)? + "\n").as_bytes())
    }

    pub fn bytes(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        self.stage(path, |tmp| std::fs::write(tmp, bytes).with_context(|| format!("cannot write {}", path.display())))
    }

    /// Moves every staged file into place, then flushes their directories.
    /// A target that is a directory, which no rename can replace, is
    /// refused before any file moves.
    pub fn commit(mut self) -> Result<()> {
        if let Some((_, path)) = self.staged.iter().find(|(_, path)| path.is_dir()) {
            bail!("cannot write {}: it is a directory", path.display());
        }
        let staged = std::mem::take(&mut self.staged);
        let mut dirs: Vec<&Path> = Vec::new();
        for (i, (tmp, path)) in staged.iter().enumerate() {
            if let Err(e) = std::fs::rename(tmp, path) {
                // The rest are removed when `self` drops.
                self.staged = staged[i..].to_vec();
                return Err(e).with_context(|| format!("cannot move output into {}", path.display()));
            }
            let dir = parent_dir(path);
            if !dirs.contains(&dir) {
                dirs.push(dir);
            }
        }
        for dir in dirs {
            sync(dir).with_context(|| format!("cannot flush directory {}", dir.display()))?;
        }
        Ok(())
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        for (tmp, _) in &self.staged {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

fn parent_dir(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

fn sync(path: &Path) -> std::io::Result<()> {
    std::fs::File::open(path).and_then(|f| f.sync_all())
}

/// An image as PNG bytes.
pub fn encode_png(image: &image::DynamicImage) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    image.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).context("cannot encode PNG")?;
    Ok(png)
}

/// Writes an f32 RGB EXR (linear sRGB) on its own.
pub fn write_exr(path: &Path, width: u32, height: u32, image: &[[f32; 3]]) -> Result<()> {
    alone(|out| out.exr(path, width, height, image))
}

/// Writes a JSON document on its own.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    alone(|out| out.json(path, value))
}

/// Writes `bytes` to `path` on its own.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    alone(|out| out.bytes(path, bytes))
}

/// One output, staged by `stage` and committed (`Outputs`).
fn alone(stage: impl FnOnce(&mut Outputs) -> Result<()>) -> Result<()> {
    let mut out = Outputs::default();
    stage(&mut out)?;
    out.commit()
}

/// Refuses an image read from `path` (`width` pixels a row) with a NaN or
/// infinite pixel, against which no error can be measured.
pub fn ensure_finite(path: &Path, width: u32, pixels: &[[f32; 3]]) -> Result<()> {
    let bad = pixels.iter().filter(|p| !p.iter().all(|c| c.is_finite())).count();
    if let Some(i) = pixels.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        let (x, y) = (i % width as usize, i / width as usize);
        bail!("{}: {bad} pixels are not finite (the first at x {x}, y {y}): no error can be measured", path.display());
    }
    Ok(())
}

/// Reads an RGB EXR into (width, height, pixels).
pub fn read_exr(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    use exr::prelude::*;
    // The crate allocates the pixels its header claims before it reads
    // them: a header that claims more than prism renders is refused first
    // (a hostile 99999^2 header aborted on a 120 GB allocation).
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
    for header in &meta.headers {
        let size = header.layer_size;
        anyhow::ensure!(
            size.area() as u64 <= crate::camera::MAX_PIXELS,
            "cannot read {}: its header claims {}x{} pixels, more than prism renders ({} pixels)",
            path.display(),
            size.width(),
            size.height(),
            crate::camera::MAX_PIXELS
        );
    }
    let img = read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0f32; 3]; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b];
        },
    )
    // (Its message only: the exr error repeats its source's in Display.)
    .map_err(|e| anyhow::anyhow!("cannot read {}: {}", path.display(), missing_rgb(&meta).unwrap_or(e.to_string())))?;
    let size = img.layer_data.size;
    let (_, px) = img.layer_data.channel_data.pixels;
    Ok((size.width() as u32, size.height() as u32, px))
}

/// What an EXR lacks for `read_exr`, if no layer has R, G and B channels
/// (the exr crate says "no layer in the image matched your specified
/// requirements").
fn missing_rgb(meta: &exr::meta::MetaData) -> Option<String> {
    let names = |h: &exr::meta::header::Header| h.channels.list.iter().map(|c| c.name.to_string()).collect::<Vec<_>>();
    let has_rgb = |n: &[String]| ["R", "G", "B"].iter().all(|c| n.iter().any(|m| m == c));
    if meta.headers.iter().any(|h| has_rgb(&names(h))) {
        return None;
    }
    let found: Vec<String> = meta.headers.iter().flat_map(names).collect();
    Some(format!("no layer has R, G and B channels (it has {})", found.join(", ")))
}

/// A linear value as an 8-bit sRGB code, clamped to [0, 1] first (NaN to 0;
/// a value an exposure scaled to infinity is white).
pub(crate) fn srgb8(c: f32) -> u8 {
    (srgb_encode(c) * 255.0 + 0.5) as u8
}

fn srgb_encode(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh directory for one test's files (its caller removes it).
    fn scratch_dir(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("prism-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Two writes of one image give the same bytes (the exr crate compresses
    /// blocks in parallel; in its default "unspecified" line order about one
    /// write in six of a small render came out in another block order).
    #[test]
    fn exr_files_depend_on_the_pixels_alone() {
        let (w, h) = (512u32, 256u32);
        // Pixels that compress to blocks of very different sizes and times.
        let image: Vec<[f32; 3]> = (0..w * h)
            .map(|i| {
                let v = if (i / w) % 128 < 64 { (i as f32 * 0.618).fract() } else { 0.25 };
                [v, v * 0.5, 1.0 - v]
            })
            .collect();
        let dir = scratch_dir("exr-bytes");
        let path = dir.join("x.exr");
        let mut first = None;
        for _ in 0..96 {
            write_exr(&path, w, h, &image).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(bytes, *first.get_or_insert_with(|| bytes.clone()), "two writes of one image differ");
        }
        assert_eq!(read_exr(&path).unwrap(), (w, h, image));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An EXR whose header claims a huge image (and carries no chunk count,
    /// which the OpenEXR library omits for one part) is refused by name
    /// before its pixels are allocated; without the check the exr crate
    /// aborted the process on a 120 GB allocation (an audit, session 42).
    #[test]
    fn an_exr_header_past_the_pixel_limit_is_refused() {
        let dir = scratch_dir("exr-huge");
        let path = dir.join("huge.exr");
        write_exr(&path, 16, 16, &[[0.5; 3]; 256]).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        // Drop the chunkCount attribute (name, type, size 4, value).
        let at = |b: &[u8], name: &[u8]| b.windows(name.len()).position(|w| w == name).unwrap();
        let chunk = at(&bytes, b"chunkCount\0int\0");
        bytes.drain(chunk..chunk + 23);
        for name in [b"dataWindow\0box2i\0".as_slice(), b"displayWindow\0box2i\0"] {
            let box2i = at(&bytes, name) + name.len() + 4;
            for (k, v) in [0i32, 0, 99_999, 99_999].iter().enumerate() {
                bytes[box2i + 4 * k..box2i + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        std::fs::write(&path, &bytes).unwrap();
        let e = read_exr(&path).unwrap_err().to_string();
        assert!(e.contains("huge.exr: its header claims 100000x100000 pixels"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An EXR without R, G and B (a luminance-only one) is refused with
    /// the channels it has, not the crate's "no layer ... matched".
    #[test]
    fn an_exr_without_rgb_names_its_channels() {
        use exr::prelude::*;
        let dir = scratch_dir("exr-y");
        let path = dir.join("luminance.exr");
        let channels =
            SpecificChannels::build().with_channel("Y").with_channel("A").with_pixel_fn(|_| (0.5f32, 1.0f32));
        Image::from_channels((4, 4), channels).write().to_file(&path).unwrap();
        let e = read_exr(&path).unwrap_err().to_string();
        assert!(e.contains("luminance.exr: no layer has R, G and B channels (it has A, Y)"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The preview's 8-bit code: clamped, with a value an exposure carried
    /// to infinity white and NaN black.
    #[test]
    fn srgb8_clamps_infinity_to_white() {
        assert_eq!(srgb8(f32::INFINITY), 255);
        assert_eq!(srgb8(1.0 * 2f32.powi(127) * 4.0), 255);
        assert_eq!(srgb8(f32::NAN), 0);
        assert_eq!(srgb8(f32::NEG_INFINITY), 0);
        assert_eq!(srgb8(0.5), 188);
    }

    /// A set of outputs whose last write fails, one of whose targets is a
    /// directory, or which stages one target twice changes none of its
    /// targets and leaves no temporary file. The control: the same set
    /// committed whole replaces every target, so the checks of the old
    /// contents can fail.
    #[test]
    fn outputs_change_no_target_unless_all_are_written() {
        let dir = scratch_dir("outputs");
        let (a, b) = (dir.join("a.json"), dir.join("b.bin"));
        std::fs::write(&a, "old a").unwrap();
        std::fs::write(&b, "old b").unwrap();
        let mut out = Outputs::default();
        out.bytes(&a, b"new a").unwrap();
        let failed = out.stage(&b, |tmp| {
            std::fs::write(tmp, "half of b").unwrap();
            bail!("disk full")
        });
        assert!(failed.is_err());
        drop(out);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "old b");
        // A target that is a directory stops the commit before any move.
        std::fs::create_dir(dir.join("c")).unwrap();
        let mut out = Outputs::default();
        out.bytes(&a, b"new a").unwrap();
        out.bytes(&dir.join("c"), b"new c").unwrap();
        assert!(out.commit().unwrap_err().to_string().contains("is a directory"));
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        std::fs::remove_dir(dir.join("c")).unwrap();
        // One target staged twice (e.g. --out inside --strategies' directory
        // under a strategy image's name) is refused when staged.
        let mut out = Outputs::default();
        out.bytes(&a, b"new a").unwrap();
        assert!(out.bytes(&a, b"again").unwrap_err().to_string().contains("would be written twice"));
        drop(out);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        let mut out = Outputs::default();
        out.bytes(&a, b"new a").unwrap();
        out.bytes(&b, b"new b").unwrap();
        out.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "new a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b");
        write_bytes(&a, b"alone").unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "alone");
        let mut names: Vec<String> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
        names.sort();
        assert_eq!(names, ["a.json", "b.bin"], "no temporary file is left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Output extensions are matched without regard to case.
    #[test]
    fn extensions_match_in_any_case() {
        assert!(ensure_extension("--png", Path::new("a.PNG"), "png").is_ok());
        assert!(ensure_extension("--png", Path::new("a.png"), "png").is_ok());
        let e = ensure_extension("--png", Path::new("a.obj"), "png").unwrap_err().to_string();
        assert_eq!(e, "--png must name a .png file, got a.obj");
        assert!(ensure_extension("--png", Path::new("png"), "png").is_err());
    }
}
