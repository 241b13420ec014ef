//! The scene loader never panics (docs/scene-format.md, "Errors"): whatever
//! the text, `prism::scene::parse_scene` returns Ok or Err, and `build()` on
//! an Ok scene returns. Thousands of mutated scene files are thrown at it:
//! byte flips, truncations, numbers replaced by hostile tokens (1e39, -0,
//! NaN-like words, u32 overflow, denormals), keys deleted or duplicated,
//! values swapped for other types, stray structural characters and multibyte
//! text. The seeds are every scene in scenes/ plus a scene that uses every
//! feature of the format (all spectrum forms, shapes, transforms, lights).
//! A deterministic sweep replaces every number of that scene by every hostile
//! token; the proptest adds random mutation chains. For longer runs, the
//! cargo-fuzz target in fuzz/ (fuzz/README.md).

#[path = "common/scenes.rs"]
mod scenes;

use prism::scene::locate::{skip_string, skip_value, skip_ws};
use prism::scene::parse_scene;
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Numbers a scene may contain that the loader must refuse or survive.
const HOSTILE_NUMBERS: &[&str] = &[
    "0",
    "-0",
    "-0.0",
    "1",
    "-1",
    "0.5",
    "1e39",
    "-1e39",
    "3.4028236e38",
    "1e308",
    "1e999",
    "-1e999",
    "1e-45",
    "1e-50",
    "4294967295",
    "4294967296",
    "18446744073709551616",
    "-2147483649",
    "180",
    "NaN",
    "nan",
    "Infinity",
    "-Infinity",
    "inf",
    "0x10",
    "1.",
    ".5",
    "+1",
    "01",
    "1e",
    "--1",
];

/// Values of other types that replace a value (type swaps).
const SWAPS: &[&str] = &[
    "\"x\"",
    "\"\"",
    "\"BK7\"",
    "\"D65\"",
    "\"white\"",
    "0",
    "-1",
    "1e39",
    "true",
    "null",
    "[]",
    "{}",
    "[1, 2, 3]",
    "[[0, 0, 0], [0, 0, 0], [0, 0, 0]]",
    "[0, 1e39, -1e39]",
    "{\"rgb\": [1, 1, 1]}",
    "{\"rgb\": [2, -1, 0], \"scale\": 1e39}",
    "{\"blackbody\": 1e38, \"scale\": 1e38}",
    "{\"wavelengths\": [500], \"values\": [1e38]}",
    "{\"wavelengths\": [], \"values\": []}",
    "{\"sellmeier\": {\"b\": [1, 1, 1], \"c\": [0.3025, 0.3025, 0.3025]}}",
    "{\"cauchy\": {\"a\": -1, \"b\": 0}}",
    "{\"cauchy\": {\"a\": 1e38, \"b\": 1e38}}",
    "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 3e38}",
    "{\"type\": \"mesh\", \"positions\": [[0, 0, 0]], \"indices\": [[0, 0, 0]], \"normals\": [[0, 0, 0]]}",
    "{\"type\": \"obj\", \"file\": \"/\"}",
    "{\"type\": \"obj\", \"file\": \"\"}",
    "{\"scale\": 1e30, \"translate\": [1e38, 0, 0]}",
];

/// Fragments inserted anywhere.
const INSERTS: &[&str] =
    &["{", "}", "[", "]", ",", ":", "\"", "\\", "\\u0000", "\u{e9}", "\u{1F600}", "\n", "/*", "\0", "0"];

fn manifest() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A directory holding the mesh files the feature scene refers to.
fn mesh_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = scenes::temp_dir("loader-fuzz");
        std::fs::write(
            d.join("tri.obj"),
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n",
        )
        .unwrap();
        d
    })
}

/// A scene that uses every construct of the format.
const FEATURES: &str = r#"{
  "comment": "every feature",
  "camera": {"position": [0, 1, -4], "look_at": [0, 0.5, 0], "up": [0, 1, 0], "fov": 45, "width": 16, "height": 12},
  "spectra": {
    "tab": {"wavelengths": [400, 550, 700], "values": [0.2, 0.5, 0.8], "scale": 1},
    "alias": "tab",
    "bb": {"blackbody": 3000, "scale": 2},
    "sell": {"sellmeier": {"b": [1.03961212, 0.231792344, 1.01046945], "c": [0.00600069867, 0.0200179144, 103.560653]}},
    "cau": {"cauchy": {"a": 1.5, "b": 0.004}}
  },
  "materials": {
    "d": {"type": "diffuse", "reflectance": {"rgb": [0.2, 0.4, 0.6], "scale": 1}},
    "t": {"type": "diffuse", "reflectance": "alias"},
    "m": {"type": "mirror", "reflectance": 0.9},
    "cu": {"type": "conductor", "metal": "Au", "roughness": 0.3},
    "ck": {"type": "conductor", "eta": 0.2, "k": 3.5, "alpha_x": 0.1, "alpha_y": 0.4},
    "g": {"type": "dielectric", "ior": "BK7", "alpha": 0.05},
    "gs": {"type": "dielectric", "ior": "sell"},
    "gc": {"type": "dielectric", "ior": "cau", "roughness": 0}
  },
  "objects": [
    {"name": "floor", "shape": {"type": "quad", "corners": [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]]}, "material": "d"},
    {"shape": {"type": "cuboid", "min": [-0.5, 0, -0.5], "max": [0.5, 1, 0.5], "inward": false}, "material": "cu",
     "transform": {"scale": [1, 2, 1], "rotate": {"axis": [0, 1, 0], "degrees": 30}, "translate": [1, 0, 0]}},
    {"shape": {"type": "sphere", "center": [-1, 0.5, 0], "radius": 0.5, "subdivisions": 2, "smooth": true, "inward": false},
     "material": "g", "transform": {"scale": 1.5}},
    {"shape": {"type": "sphere", "center": [0, 0.5, 1], "radius": 0.3, "subdivisions": 1}, "material": "gs"},
    {"shape": {"type": "mesh", "positions": [[0, 2, 0], [1, 2, 0], [0, 2, 1]], "indices": [[0, 1, 2]],
     "normals": [[0, -1, 0], [0, -1, 0], [0, 0, 0]]}, "material": "t", "emission": {"blackbody": 5000, "scale": 3}, "two_sided": true},
    {"comment": "a mesh from a file", "shape": {"type": "obj", "file": "tri.obj"}, "material": "ck"},
    {"shape": {"type": "quad", "corners": [[0, 3, 0], [1, 3, 0], [1, 3, 1], [0, 3, 1]]}, "material": "m", "emission": "bb"},
    {"shape": {"type": "cuboid", "min": [2, 0, 2], "max": [3, 1, 3], "inward": true}, "material": "gc", "emission": {"rgb": [1, 0.5, 0.2], "scale": 2}},
    {"shape": {"type": "quad", "corners": [[0, 4, 0], [1, 4, 0], [1, 4, 1], [0, 4, 1]]}, "material": "d", "emission": {"wavelengths": [380, 780], "values": [1, 2]}}
  ],
  "lights": [
    {"type": "point", "name": "p", "position": [0, 3, 0], "intensity": "D65"},
    {"type": "point", "position": [1, 3, 0], "intensity": {"rgb": [1, 1, 1], "scale": 5}},
    {"type": "environment", "name": "sky", "radiance": {"rgb": [0.1, 0.2, 0.3]}}
  ],
  "render": {"spp": 4, "max_depth": 5, "integrator": "bdpt", "seed": 7}
}
"#;

/// The seed texts: the feature scene, then every scene in scenes/.
fn seeds() -> &'static [(String, String)] {
    static SEEDS: OnceLock<Vec<(String, String)>> = OnceLock::new();
    SEEDS.get_or_init(|| {
        let mut v = vec![("features.json".to_string(), FEATURES.to_string())];
        let mut files: Vec<PathBuf> = std::fs::read_dir(manifest().join("scenes"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "json"))
            .collect();
        files.sort();
        for f in files {
            v.push((f.file_name().unwrap().to_string_lossy().to_string(), std::fs::read_to_string(&f).unwrap()));
        }
        v
    })
}

/// Parses and builds; the only acceptable outcomes are Ok and Err. Returns
/// whether the scene loaded.
fn load(text: &str) -> bool {
    match parse_scene(text, "fuzz.json", mesh_dir()) {
        Ok(b) => {
            let scene = b.build();
            let _ = scene.triangle_count();
            true
        }
        Err(e) => {
            // Every error is a complete sentence that names the file.
            let s = e.to_string();
            assert!(s.starts_with("fuzz.json") && !e.message.is_empty(), "bad error: {s:?}");
            false
        }
    }
}

// ------------------------------------------------------------- JSON scanning

/// End (exclusive) of the non-empty JSON value starting at `i`.
fn value_end(b: &[u8], i: usize) -> Option<usize> {
    skip_value(b, i).filter(|&j| j > i)
}

/// (key start, value start, value end) of every `"key": value` member.
fn members(text: &str) -> Vec<(usize, usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'"' {
            let Some(end) = skip_string(b, i) else { break };
            let c = skip_ws(b, end);
            if b.get(c) == Some(&b':') {
                let v = skip_ws(b, c + 1);
                if let Some(ve) = value_end(b, v) {
                    out.push((i, v, ve));
                }
            }
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// (start, end) of every number token outside strings.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'"' => i = skip_string(b, i).unwrap_or(b.len()),
            c if c == b'-' || c.is_ascii_digit() => {
                let s = i;
                while i < b.len() && matches!(b[i], b'-' | b'+' | b'.' | b'e' | b'E' | b'0'..=b'9') {
                    i += 1;
                }
                out.push((s, i));
            }
            _ => i += 1,
        }
    }
    out
}

/// Picks element `frac` (in [0, 1)) of a list.
fn pick<T: Copy>(v: &[T], frac: f64) -> Option<T> {
    (!v.is_empty()).then(|| v[((frac * v.len() as f64) as usize).min(v.len() - 1)])
}

/// A char boundary at or before byte `frac * len`.
fn boundary(text: &str, frac: f64) -> usize {
    let mut i = ((frac * text.len() as f64) as usize).min(text.len());
    while !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

#[derive(Clone, Debug)]
enum Mutation {
    FlipByte(f64, u8),
    Truncate(f64),
    ReplaceNumber(f64, usize),
    DeleteMember(f64),
    DuplicateMember(f64),
    SwapValue(f64, usize),
    Insert(f64, usize),
}

fn apply(text: String, m: &Mutation) -> String {
    match *m {
        Mutation::FlipByte(at, byte) => {
            let mut b = text.into_bytes();
            if !b.is_empty() {
                let i = ((at * b.len() as f64) as usize).min(b.len() - 1);
                b[i] = byte;
            }
            String::from_utf8_lossy(&b).into_owned()
        }
        Mutation::Truncate(at) => text[..boundary(&text, at)].to_string(),
        Mutation::ReplaceNumber(at, k) => match pick(&numbers(&text), at) {
            Some((s, e)) => format!("{}{}{}", &text[..s], HOSTILE_NUMBERS[k % HOSTILE_NUMBERS.len()], &text[e..]),
            None => text,
        },
        Mutation::DeleteMember(at) => match pick(&members(&text), at) {
            Some((k, _, ve)) => {
                // Take the member's trailing comma, else its leading one.
                let b = text.as_bytes();
                let after = skip_ws(b, ve);
                if b.get(after) == Some(&b',') {
                    format!("{}{}", &text[..k], &text[after + 1..])
                } else {
                    let before = text[..k].trim_end();
                    let cut = if before.ends_with(',') { before.len() - 1 } else { k };
                    format!("{}{}", &text[..cut], &text[ve..])
                }
            }
            None => text,
        },
        Mutation::DuplicateMember(at) => match pick(&members(&text), at) {
            Some((k, _, ve)) => format!("{}, {}{}", &text[..ve], &text[k..ve], &text[ve..]),
            None => text,
        },
        Mutation::SwapValue(at, s) => match pick(&members(&text), at) {
            Some((_, v, ve)) => format!("{}{}{}", &text[..v], SWAPS[s % SWAPS.len()], &text[ve..]),
            None => text,
        },
        Mutation::Insert(at, s) => {
            let i = boundary(&text, at);
            format!("{}{}{}", &text[..i], INSERTS[s % INSERTS.len()], &text[i..])
        }
    }
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let at = 0.0..1.0f64;
    prop_oneof![
        2 => (at.clone(), any::<u8>()).prop_map(|(a, b)| Mutation::FlipByte(a, b)),
        1 => at.clone().prop_map(Mutation::Truncate),
        4 => (at.clone(), any::<usize>()).prop_map(|(a, k)| Mutation::ReplaceNumber(a, k)),
        2 => at.clone().prop_map(Mutation::DeleteMember),
        2 => at.clone().prop_map(Mutation::DuplicateMember),
        3 => (at.clone(), any::<usize>()).prop_map(|(a, k)| Mutation::SwapValue(a, k)),
        1 => (at, any::<usize>()).prop_map(|(a, k)| Mutation::Insert(a, k)),
    ]
}

/// Cases for the random test; PRISM_FUZZ_CASES overrides (e.g. 100000 for a
/// long local run). A value that is not a positive whole number is an
/// error: falling back to the default, or running no case, would let a
/// long run pass untested.
fn cases() -> u32 {
    let n = scenes::seeds::from_env("PRISM_FUZZ_CASES", 3000);
    assert!(n > 0 && n <= u32::MAX as u64, "PRISM_FUZZ_CASES={n}: not a positive number of cases");
    n as u32
}

#[test]
fn seed_scenes_load() {
    for (name, text) in seeds() {
        assert!(parse_scene(text, name, &manifest().join("scenes")).is_ok() || name == "features.json", "{name}");
    }
    assert!(load(FEATURES), "{}", parse_scene(FEATURES, "features.json", mesh_dir()).err().unwrap());
}

/// Every number of the feature scene replaced by every hostile token, one at
/// a time; and every member deleted, duplicated, and swapped for every other
/// type, one at a time.
#[test]
fn every_single_edit_of_the_feature_scene() {
    let text = FEATURES.to_string();
    let (mut ok, mut err) = (0, 0);
    let mut count = |loaded: bool| if loaded { ok += 1 } else { err += 1 };
    for &(s, e) in &numbers(&text) {
        for t in HOSTILE_NUMBERS {
            count(load(&format!("{}{}{}", &text[..s], t, &text[e..])));
        }
    }
    let n = members(&text).len();
    for k in 0..n {
        let at = (k as f64 + 0.5) / n as f64;
        count(load(&apply(text.clone(), &Mutation::DeleteMember(at))));
        count(load(&apply(text.clone(), &Mutation::DuplicateMember(at))));
        for s in 0..SWAPS.len() {
            count(load(&apply(text.clone(), &Mutation::SwapValue(at, s))));
        }
    }
    eprintln!("single edits: {ok} loaded, {err} refused");
    assert!(ok > 100 && err > 100, "the sweep should exercise both outcomes: {ok} ok, {err} errors");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn mutated_scenes_never_panic(seed in any::<usize>(), edits in proptest::collection::vec(mutation(), 1..5)) {
        let seeds = seeds();
        let text = edits.iter().fold(seeds[seed % seeds.len()].1.clone(), apply);
        load(&text);
    }
}
