//! The accumulation state of a render: the film's exact sums (film.rs), which
//! sample indices they hold, and what was rendered (scene, integrator, seed,
//! resolution, ...). It is what a checkpoint stores (`--checkpoint-every`,
//! `--resume`) and what a part of a split render leaves for `prism merge`
//! (`--sample-range`), so that resumed and merged renders are bit-identical
//! to one uninterrupted run (docs/cluster.md).
//!
//! File format, version 2 (little-endian; version 1, read too, is the same
//! without the header's provenance):
//!
//! | bytes          | content                                               |
//! |----------------|-------------------------------------------------------|
//! | 8              | magic `PRISMST\0`                                     |
//! | 4              | format version (u32)                                  |
//! | 4              | header length n (u32)                                 |
//! | n              | header: JSON `Header` (identity, sample ranges,       |
//! |                | dropped samples, provenance: commit, build target)    |
//! | 48 x w x h     | the film's sums, row-major, r g b as i128             |
//! | 8              | FNV-1a 64 of everything before (u64)                  |
//!
//! Loading checks all of it, so a truncated, corrupt or foreign file is a
//! clear error rather than a wrong image.

use crate::film::{DroppedSamples, Film};
use crate::output::write_bytes;
use anyhow::{bail, ensure, Context, Result};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"PRISMST\0";
const VERSION: u32 = 2;
/// The oldest version read: 1, whose header has no provenance. (A
/// prism that reads version 1 only refuses version 2 by its number.)
const OLDEST_VERSION: u32 = 1;

/// The largest state file: the fixed fields, a header of up to 64 MiB (its
/// sample ranges), and the sums of the largest film.
const MAX_STATE_BYTES: u64 = 24 + (64 << 20) + 48 * crate::camera::MAX_PIXELS;

/// What makes two renders' sums addable: same scene content, estimator,
/// seed, resolution and estimator options.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Identity {
    /// The scene file as it was named (for people: parts rendered on other
    /// machines may name it differently; `scene_hash` is what is compared).
    pub scene: String,
    /// FNV-1a 64 of the scene file's bytes, in hex.
    pub scene_hash: String,
    pub integrator: String,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    pub max_depth: u32,
    pub mis: String,
}

impl Identity {
    /// Fails, naming the first field that differs, unless `other` (from
    /// `other_name`) may be added to `self` (from `name`).
    pub fn ensure_same(&self, name: &str, other: &Identity, other_name: &str) -> Result<()> {
        let (a, b) = (serde_json::to_value(self)?, serde_json::to_value(other)?);
        let (serde_json::Value::Object(a), serde_json::Value::Object(b)) = (a, b) else { unreachable!() };
        for (field, value) in a.iter().filter(|(f, _)| f.as_str() != "scene") {
            if b[field] != *value {
                bail!("{other_name} has {field} {} but {name} has {value}", b[field]);
            }
        }
        Ok(())
    }
}

/// The JSON header of a state file.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    identity: Identity,
    /// Sample indices held, as sorted disjoint [start, end) ranges.
    sample_ranges: Vec<[u32; 2]>,
    dropped: DroppedSamples,
    /// `Provenance::build_target` (absent in version 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    build_target: Option<String>,
    /// `Provenance::commit` (absent in version 1, and in the version 2
    /// files of session 39's binaries before def4b1e).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    commit: Option<String>,
}

/// A film together with what it holds.
pub struct RenderState {
    pub identity: Identity,
    /// Sample indices held, sorted and disjoint; their total is `film.spp`.
    pub sample_ranges: Vec<Range<u32>>,
    pub film: Film,
    pub provenance: Provenance,
}

/// Which prism rendered a state's sums: the commit and the build target
/// (`crate::build_target`), each a list joined by "; " once sums of
/// several are added (`combined`), "not recorded" for a version 1 file.
/// Images are bit-identical within one commit and build target only (FMA
/// rounds differently; the renderer may change between commits), so sums
/// of two make an unbiased image that neither may render.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Provenance {
    pub commit: String,
    pub build_target: String,
}

/// A version 1 file's provenance, either half.
pub const UNRECORDED: &str = "not recorded";

impl Provenance {
    /// This binary's.
    pub fn this() -> Self {
        Provenance { commit: env!("PRISM_COMMIT").to_string(), build_target: crate::build_target() }
    }

    /// Of the sums of both: each commit and build named once, sorted.
    pub fn combined(&self, other: &Provenance) -> Provenance {
        let join = |a: &str, b: &str| {
            let mut names: Vec<&str> = a.split("; ").chain(b.split("; ")).collect();
            names.sort_unstable();
            names.dedup();
            names.join("; ")
        };
        Provenance {
            commit: join(&self.commit, &other.commit),
            build_target: join(&self.build_target, &other.build_target),
        }
    }

    /// Whether more than one commit or build (or an unrecorded one) made
    /// the sums.
    pub fn is_mixed(&self) -> bool {
        self.commit.contains("; ") || self.build_target.contains("; ")
    }
}

impl RenderState {
    /// The samples held, when they are one contiguous range.
    pub fn contiguous_range(&self) -> Option<Range<u32>> {
        match self.sample_ranges.as_slice() {
            [r] => Some(r.clone()),
            _ => None,
        }
    }

    /// Adds parts (name, state) of one image into one state: refuses parts of
    /// different renders (`Identity`) and parts whose samples overlap. The
    /// parts are taken one at a time (loaded as they come, each dropped once
    /// added: memory for two films, the sum and one part, not for every
    /// part).
    pub fn merge(parts: impl IntoIterator<Item = Result<(String, RenderState)>>) -> Result<RenderState> {
        let mut parts = parts.into_iter();
        let (first_name, mut merged) = parts.next().context("nothing to merge")??;
        let mut owners: Vec<(Range<u32>, String)> =
            merged.sample_ranges.iter().map(|r| (r.clone(), first_name.clone())).collect();
        for part in parts {
            let (name, part) = part?;
            merged.identity.ensure_same(&first_name, &part.identity, &name)?;
            merged.provenance = merged.provenance.combined(&part.provenance);
            owners.extend(part.sample_ranges.iter().map(|r| (r.clone(), name.clone())));
            merged.film.add(&part.film).with_context(|| format!("adding {name}"))?;
        }
        owners.retain(|(r, _)| !r.is_empty());
        owners.sort_by_key(|(r, _)| (r.start, r.end));
        for w in owners.windows(2) {
            let ((a, an), (b, bn)) = (&w[0], &w[1]);
            ensure!(
                b.start >= a.end,
                "{bn} has samples {b:?}, which overlap {an}'s {a:?}: each sample must be counted once"
            );
        }
        merged.sample_ranges = coalesce(owners.into_iter().map(|(r, _)| r));
        Ok(merged)
    }

    /// Writes a state durably (temporary file, fsync, rename). It takes the
    /// parts, not a `RenderState`: a render in progress owns its film apart.
    pub fn save(
        path: &Path,
        identity: &Identity,
        sample_ranges: &[Range<u32>],
        film: &Film,
        provenance: &Provenance,
    ) -> Result<()> {
        write_bytes(path, &Self::encode(identity, sample_ranges, film, provenance)?)
    }

    /// A state file's bytes (the layout above), of sums rendered by
    /// `provenance`.
    pub fn encode(
        identity: &Identity,
        sample_ranges: &[Range<u32>],
        film: &Film,
        provenance: &Provenance,
    ) -> Result<Vec<u8>> {
        let header = Header {
            identity: identity.clone(),
            sample_ranges: sample_ranges.iter().map(|r| [r.start, r.end]).collect(),
            dropped: film.dropped,
            build_target: Some(provenance.build_target.clone()),
            commit: Some(provenance.commit.clone()),
        };
        Self::encode_version(VERSION, &header, film)
    }

    fn encode_version(version: u32, header: &Header, film: &Film) -> Result<Vec<u8>> {
        let header = serde_json::to_vec(header)?;
        let mut bytes = Vec::with_capacity(24 + header.len() + film.sums.len() * 48);
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&version.to_le_bytes());
        bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
        bytes.extend_from_slice(&header);
        for c in film.sums.iter().flatten() {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        bytes.extend_from_slice(&fnv1a(&bytes).to_le_bytes());
        Ok(bytes)
    }

    /// Reads and validates a state file; errors name the file and the fault.
    /// Only a regular file no larger than a state can be is read (a device
    /// or a FIFO would never end).
    pub fn load(path: &Path) -> Result<RenderState> {
        let meta = std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?;
        ensure!(meta.is_file(), "cannot read {}: not a regular file", path.display());
        ensure!(
            meta.len() <= MAX_STATE_BYTES,
            "{}: {} bytes, more than a state file of the largest film holds",
            path.display(),
            meta.len()
        );
        let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        Self::parse(&bytes).with_context(|| format!("{}: not a usable prism state file", path.display()))
    }

    fn parse(bytes: &[u8]) -> Result<RenderState> {
        ensure!(bytes.len() >= 24 && bytes.starts_with(MAGIC), "no prism state header (bad magic)");
        let version = u32::from_le_bytes(bytes[8..12].try_into()?);
        ensure!(
            (OLDEST_VERSION..=VERSION).contains(&version),
            "format version {version}; this prism reads versions {OLDEST_VERSION} to {VERSION}"
        );
        let (body, sum) = bytes.split_at(bytes.len() - 8);
        ensure!(
            fnv1a(body) == u64::from_le_bytes(sum.try_into()?),
            "truncated or corrupt: checksum mismatch ({} bytes)",
            bytes.len()
        );
        let n = u32::from_le_bytes(bytes[12..16].try_into()?) as usize;
        let json = body.get(16..16 + n).context("header length beyond the end of the file")?;
        let header: Header = serde_json::from_slice(json).context("header")?;
        let (w, h) = (header.identity.width, header.identity.height);
        // prism never writes an empty or oversized film; an image of one
        // could not be written (or read back).
        crate::camera::Camera::check_resolution(w, h).map_err(|e| anyhow::anyhow!("film size: {e}"))?;
        let data = &body[16 + n..];
        ensure!(
            data.len() == w as usize * h as usize * 48,
            "{} bytes of sums, expected {} for a {w}x{h} film",
            data.len(),
            w as usize * h as usize * 48
        );
        let ranges: Vec<Range<u32>> = header.sample_ranges.iter().map(|r| r[0]..r[1]).collect();
        ensure!(
            !ranges.is_empty()
                && ranges.iter().all(|r| r.start <= r.end)
                && ranges.windows(2).all(|p| p[0].end < p[1].start),
            "sample_ranges {:?} are not sorted, disjoint ranges",
            header.sample_ranges
        );
        let mut film = Film::new(w, h);
        for (sum, bytes) in film.sums.iter_mut().flatten().zip(data.chunks_exact(16)) {
            *sum = i128::from_le_bytes(bytes.try_into()?);
        }
        film.spp = ranges.iter().map(|r| r.len() as u64).sum();
        ensure!(
            film.spp > 0 || film.sums.iter().flatten().all(|&c| c == 0),
            "sums without samples (sample_ranges empty)"
        );
        film.dropped = header.dropped;
        let recorded = |field: Option<String>| field.unwrap_or_else(|| UNRECORDED.to_string());
        let provenance = Provenance { commit: recorded(header.commit), build_target: recorded(header.build_target) };
        Ok(RenderState { identity: header.identity, sample_ranges: ranges, film, provenance })
    }
}

/// Joins touching ranges of a sorted, disjoint list (keeps one empty range
/// if there is nothing else, so a state always names where it starts).
fn coalesce(ranges: impl Iterator<Item = Range<u32>>) -> Vec<Range<u32>> {
    let mut out: Vec<Range<u32>> = Vec::new();
    for r in ranges {
        match out.last_mut() {
            Some(last) if last.end == r.start => last.end = r.end,
            _ => out.push(r),
        }
    }
    if out.is_empty() {
        out.push(0..0);
    }
    out
}

/// A scene file as a render's records name it: as it was given, and by
/// its content and that of every file it reads (what is compared:
/// `Identity::scene_hash`).
#[derive(Clone, Debug)]
pub struct SceneFingerprint {
    pub name: String,
    /// FNV-1a 64, in hex, of the scene file's bytes followed, for each file
    /// it reads or names (`SceneBuilder::inputs`: meshes, buffers, images,
    /// included glTF), by that file's length (8 bytes, little-endian) and
    /// bytes, or 2^64 - 1 for one it cannot read (a glTF may name an image
    /// no material uses, or one missing, which the loader warns of). A
    /// scene that reads no other file keeps the hash of its own bytes.
    pub hash: String,
}

impl SceneFingerprint {
    /// The fingerprint of the scene file `path` and the files it reads,
    /// `inputs`: an edit of a mesh between the parts of a render, or
    /// between a checkpoint and its resume, is a different scene (only the
    /// scene file was hashed; from an audit, session 50).
    pub fn read(path: &Path, inputs: &[PathBuf]) -> Result<Self> {
        let scene = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut hash = fnv1a_from(FNV1A_BASIS, &scene);
        for input in inputs {
            hash = match std::fs::read(input) {
                Ok(bytes) => fnv1a_from(fnv1a_from(hash, &(bytes.len() as u64).to_le_bytes()), &bytes),
                Err(_) => fnv1a_from(hash, &u64::MAX.to_le_bytes()),
            };
        }
        Ok(SceneFingerprint { name: path.display().to_string(), hash: format!("{hash:016x}") })
    }
}

const FNV1A_BASIS: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a, 64 bits: a checksum for state files and the scene's identity
/// (not cryptographic; it catches accidents, not adversaries).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_from(FNV1A_BASIS, bytes)
}

/// FNV-1a continued from the hash `h` of the bytes before `bytes`.
fn fnv1a_from(h: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(h, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(seed: u64, range: Range<u32>) -> RenderState {
        let identity = Identity {
            scene: "s.json".into(),
            scene_hash: "0".into(),
            integrator: "path".into(),
            seed,
            width: 2,
            height: 1,
            max_depth: 5,
            mis: "power".into(),
        };
        let mut film = Film::new(2, 1);
        film.sums = vec![[1, -2, i128::MAX / 4], [3, 4, 5]];
        film.spp = range.len() as u64;
        RenderState { identity, sample_ranges: vec![range], film, provenance: provenance("abc", "x86_64 +avx2 +fma") }
    }

    fn provenance(commit: &str, build_target: &str) -> Provenance {
        Provenance { commit: commit.into(), build_target: build_target.into() }
    }

    #[test]
    fn round_trips_and_rejects_damage() {
        let s = state(1, 16..32);
        let dir = std::env::temp_dir().join(format!("prism-state-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.state");
        RenderState::save(&path, &s.identity, &s.sample_ranges, &s.film, &provenance("abc", "x86_64")).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let back = RenderState::parse(&bytes).unwrap();
        assert_eq!(
            (back.identity, back.sample_ranges, back.film.sums, back.film.spp),
            (s.identity, s.sample_ranges, s.film.sums, 16)
        );
        let err = |b: &[u8]| RenderState::parse(b).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err(&bytes[..bytes.len() - 1]).contains("checksum"));
        let mut flipped = bytes.clone();
        flipped[40] ^= 1;
        assert!(err(&flipped).contains("checksum"));
        assert!(err(b"P6 not a state file at all").contains("magic"));
        let mut future = bytes.clone();
        future[8] = 9;
        assert!(err(&future).contains("version 9"));
        // A well-formed state of an empty film (which prism never writes).
        let mut empty = state(1, 0..1);
        empty.identity.width = 0;
        empty.film = Film::new(0, 1);
        RenderState::save(&path, &empty.identity, &empty.sample_ranges, &empty.film, &provenance("abc", "x86_64"))
            .unwrap();
        let e = RenderState::load(&path).err().map(|e| format!("{e:#}")).unwrap_or_default();
        assert!(e.contains("film size: width and height must be at least 1"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn merge(parts: Vec<(String, RenderState)>) -> Result<RenderState> {
        RenderState::merge(parts.into_iter().map(Ok))
    }

    #[test]
    fn merge_adds_and_refuses_mismatch_or_overlap() {
        let m = merge(vec![("b".into(), state(1, 16..32)), ("a".into(), state(1, 0..16))]).unwrap();
        assert_eq!(
            (m.sample_ranges.as_slice(), m.film.spp, m.film.sums[1]),
            (std::slice::from_ref(&(0..32)), 32, [6, 8, 10])
        );
        let e = merge(vec![("a".into(), state(1, 0..16)), ("b".into(), state(2, 16..32))]);
        assert!(e.err().unwrap().to_string().contains("b has seed 2 but a has 1"));
        let e = merge(vec![("a".into(), state(1, 0..16)), ("b".into(), state(1, 8..24))]);
        assert!(e.err().unwrap().to_string().contains("overlap"));
        // Sums beyond the exact range name the part that took them there
        // (the fifth i128::MAX / 4), and dropped counts saturate, not wrap.
        let parts = [0..16, 16..32, 32..48, 48..64, 64..80].map(|r| (format!("p{}", r.start), state(1, r)));
        let e = merge(parts.into());
        let e = e.err().map(|e| format!("{e:#}")).unwrap_or_default();
        assert!(e.starts_with("adding p64: the summed samples leave the film's exact range"), "{e}");
        let mut a = state(1, 0..16);
        a.film.dropped.nan = u64::MAX;
        let m = merge(vec![("a".into(), a), ("b".into(), state(1, 16..32))]).unwrap();
        assert_eq!((m.film.dropped.nan, m.film.dropped.total()), (u64::MAX, u64::MAX));
    }

    /// From a review (session 39): a merge records every commit and build
    /// that rendered its parts (with and without AVX2 and FMA, say), each
    /// once, however often it merges, and a version 1 file's (which
    /// records neither) as "not recorded". They survive the file, and a
    /// version 1 file is still read.
    #[test]
    fn a_merge_records_the_builds_of_its_parts() {
        let other = |range| RenderState { provenance: provenance("def", "x86_64"), ..state(1, range) };
        let m = merge(vec![("a".into(), state(1, 0..16)), ("b".into(), other(16..32))]).unwrap();
        assert_eq!(m.provenance, provenance("abc; def", "x86_64; x86_64 +avx2 +fma"));
        assert!(m.provenance.is_mixed() && !state(1, 0..1).provenance.is_mixed());
        let again = merge(vec![("m".into(), m), ("d".into(), other(48..64))]).unwrap();
        assert_eq!(again.provenance, provenance("abc; def", "x86_64; x86_64 +avx2 +fma"));
        let bytes = RenderState::encode(&again.identity, &again.sample_ranges, &again.film, &again.provenance);
        assert_eq!(RenderState::parse(&bytes.unwrap()).unwrap().provenance, again.provenance);
        let header = |recorded: Option<&str>| Header {
            identity: again.identity.clone(),
            sample_ranges: vec![[64, 80]],
            dropped: DroppedSamples::default(),
            build_target: recorded.map(str::to_string),
            commit: recorded.map(str::to_string),
        };
        let v1 = RenderState::encode_version(1, &header(None), &again.film).unwrap();
        let v1 = RenderState::parse(&v1).unwrap();
        assert_eq!(v1.provenance, provenance(UNRECORDED, UNRECORDED), "a version 1 header");
        let mixed = merge(vec![("v1".into(), v1), ("d".into(), other(80..96))]).unwrap();
        assert_eq!(mixed.provenance, provenance("def; not recorded", "not recorded; x86_64"));
        let v3 = RenderState::encode_version(3, &header(Some("x86_64")), &again.film).unwrap();
        let e = RenderState::parse(&v3).err().map(|e| e.to_string()).unwrap_or_default();
        assert_eq!(e, "format version 3; this prism reads versions 1 to 2");
    }

    /// From an audit: a state of no samples whose sums are not zero (prism
    /// writes none; one would add garbage to a merge) is refused, and so is
    /// a file that is no regular file (`/dev/zero` was read until memory
    /// ran out).
    #[test]
    fn refuses_sums_without_samples_and_files_that_are_no_state() {
        let dir = std::env::temp_dir().join(format!("prism-state-odd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.state");
        let s = state(1, 0..0);
        RenderState::save(&path, &s.identity, &s.sample_ranges, &s.film, &provenance("abc", "x86_64")).unwrap();
        let e = RenderState::load(&path).err().map(|e| format!("{e:#}")).unwrap_or_default();
        assert!(e.contains("sums without samples"), "{e}");
        let mut zero = state(1, 0..0);
        zero.film = Film::new(2, 1);
        RenderState::save(&path, &zero.identity, &zero.sample_ranges, &zero.film, &provenance("abc", "x86_64"))
            .unwrap();
        assert!(RenderState::load(&path).is_ok(), "a state of no samples and zero sums");
        for odd in [Path::new("/dev/zero"), dir.as_path()] {
            let e = RenderState::load(odd).err().map(|e| format!("{e:#}")).unwrap_or_default();
            assert!(e.contains("not a regular file"), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
