//! Bad input to `prism render`: one test case per row of the "Errors" table
//! in docs/scene-format.md that tests/cli.rs does not already cover. Each
//! case must exit non-zero with one clear message (a single `error:` line)
//! that names the file, line and column and the field (or, for command-line
//! problems, the flag or path), and must leave an existing output file and
//! its sidecar untouched (no temporary file left either).
//!
//! `error_table_matches_the_tests` keeps the table and the tests in step:
//! every row names a case here or a test function in tests/cli.rs, and
//! every case here has a row.

#[path = "common/scenes.rs"]
mod scenes;

use scenes::temp_dir;

use std::path::{Path, PathBuf};
use std::process::Command;

/// What a case changes: the scene text and/or the command line.
struct Case {
    id: &'static str,
    /// (from, to) replacements applied to scenes::TINY_SCENE, in order (`to` = TRUNCATE:
    /// the text ends where `from` starts).
    edits: &'static [(&'static str, &'static str)],
    /// Extra arguments; `{dir}` is the case's directory.
    args: &'static [&'static str],
    /// Output EXR, relative to the case's directory unless absolute.
    out: &'static str,
    /// Expected in the one error line: the scene file's position prefix
    /// (`s.json:L:`, empty for command-line errors) and words.
    position: &'static str,
    words: &'static [&'static str],
}

/// A sphere of 9 subdivisions (5,242,880 triangles) as a scene object.
macro_rules! sphere9 {
    () => {
        "{\"shape\": {\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"subdivisions\": 9}, \"material\": \"white\"}, "
    };
}

macro_rules! five_spheres {
    () => {
        concat!(sphere9!(), sphere9!(), sphere9!(), sphere9!(), sphere9!())
    };
}

const CASES: &[Case] = &[
    Case {
        id: "truncated",
        edits: &[("  \"objects\"", TRUNCATE)],
        args: &[],
        out: "out.exr",
        position: "s.json:4:1:",
        words: &["EOF while parsing a value"],
    },
    Case {
        id: "trailing-text",
        edits: &[("1.0}]\n}", "1.0}]\n}\n}")],
        args: &[],
        out: "out.exr",
        position: "s.json:7:1:",
        words: &["trailing characters"],
    },
    Case {
        id: "zero-height",
        edits: &[("\"height\": 8", "\"height\": 0")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:93:",
        words: &["camera.height: width and height must be at least 1"],
    },
    Case {
        id: "unused-spectrum",
        edits: &[("  \"materials\"", "  \"spectra\": {\"x\": -1},\n  \"materials\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:20:",
        words: &["spectra.x: a spectrum value must be a finite number >= 0, got -1"],
    },
    Case {
        // Reported where the names are defined, not where the first is used (line 7).
        id: "spectrum-cycle",
        edits: &[
            ("  \"materials\"", "  \"spectra\": {\n    \"a\": \"b\",\n    \"b\": \"a\"\n  },\n  \"materials\""),
            ("\"reflectance\": 0.5", "\"reflectance\": \"a\""),
        ],
        args: &[],
        out: "out.exr",
        position: "s.json:4:10:",
        words: &["spectra.a: spectra \"a\" -> \"b\" -> \"a\" form a cycle"],
    },
    Case {
        id: "spectrum-names-itself",
        edits: &[("  \"materials\"", "  \"spectra\": {\"x\": \"x\"},\n  \"materials\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:20:",
        words: &["spectra.x: spectrum \"x\" names itself"],
    },
    Case {
        id: "negative-wavelengths",
        edits: &[("\"reflectance\": 0.5", "\"reflectance\": {\"wavelengths\": [-500, -400], \"values\": [0.5, 0.2]}")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:61:",
        words: &["materials.white.reflectance: \"wavelengths\" are in nanometres, all above 0"],
    },
    Case {
        // Cauchy: n = a + b / l^2 with b < 0 is negative in the blue: 0.5 - 0.2 / 0.36^2 at 360 nm.
        id: "negative-cauchy",
        edits: &[("\"reflectance\": 0.5", "\"reflectance\": {\"cauchy\": {\"a\": 0.5, \"b\": -0.2}}")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:61:",
        words: &["materials.white.reflectance: spectrum values must be >= 0 (min -1.043)"],
    },
    Case {
        id: "huge-extinction",
        edits: &[("{\"type\": \"diffuse\", \"reflectance\": 0.5}", "{\"type\": \"conductor\", \"eta\": 1, \"k\": 1e10, \"roughness\": 0.5}")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:63:",
        words: &["materials.white.k: must be at most 1e6 (max 1e10)"],
    },
    Case {
        // An rgb `k` is a shape in [0, 1], as a reflectance is; `scale` is its magnitude.
        id: "rgb-extinction-above-one",
        edits: &[(
            "{\"type\": \"diffuse\", \"reflectance\": 0.5}",
            "{\"type\": \"conductor\", \"eta\": 1, \"k\": {\"rgb\": [3, 3, 3]}}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &["materials.white.k: an rgb other than an emission is a shape in [0, 1]; \"scale\" sets its magnitude"],
    },
    Case {
        id: "tiny-ior",
        edits: &[("{\"type\": \"diffuse\", \"reflectance\": 0.5}", "{\"type\": \"dielectric\", \"ior\": 1e-20, \"roughness\": 0.5}")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:56:",
        words: &["materials.white.ior: must be at least 1e-6 (min 1e-20)"],
    },
    Case {
        id: "ior-near-one",
        edits: &[("{\"type\": \"diffuse\", \"reflectance\": 0.5}", "{\"type\": \"dielectric\", \"ior\": 1.00001, \"roughness\": 0.5}")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:56:",
        words: &["materials.white.ior: a rough dielectric's ior must be 1 or differ from 1 by at least 2.00e-4 at alpha 0.25, its narrower (here 1.00001 to 1.00001)"],
    },
    Case {
        id: "cold-blackbody",
        edits: &[("\"radiance\": 1.0", "\"radiance\": {\"blackbody\": 1}")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:50:",
        words: &["lights[0].radiance: a blackbody at 1 K emits no visible light to normalise"],
    },
    Case {
        id: "nan-token",
        edits: &[("\"fov\": 40", "\"fov\": NaN")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.fov", "expected value"],
    },
    Case {
        id: "infinity-token",
        edits: &[("\"radius\": 1", "\"radius\": -Infinity")],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.radius: invalid number"],
    },
    Case {
        id: "f32-overflow",
        edits: &[("[0, 0, -3]", "[0, 0, -1e39]")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.position: numbers must be finite"],
    },
    Case {
        // serde's arrays stop after 3 and called the 4th "trailing characters".
        id: "vector-too-long",
        edits: &[("[0, 0, -3]", "[0, 0, -3, 1]")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.position: expected 3 numbers [x, y, z], got 4"],
    },
    Case {
        id: "vector-too-short",
        edits: &[("[0, 0, -3]", "[0, -3]")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.position: expected 3 numbers [x, y, z], got 2"],
    },
    Case {
        id: "quad-corner-count",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"quad\", \"corners\": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0]]}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.corners: expected 4 points [x, y, z], got 5"],
    },
    Case {
        id: "triangle-index-count",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"mesh\", \"positions\": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], \"indices\": [[0, 1, 2, 0]]}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.indices[0]: expected 3 vertex indices, got 4"],
    },
    Case {
        id: "mesh-without-triangles",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"mesh\", \"positions\": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], \"indices\": []}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.indices: no triangles"],
    },
    Case {
        id: "two-sided-without-emission",
        edits: &[("\"material\": \"white\"}]", "\"material\": \"white\", \"two_sided\": true}]")],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].two_sided: applies to an emitter only"],
    },
    Case {
        id: "spectrum-overflow",
        edits: &[("\"radiance\": 1.0", "\"radiance\": {\"rgb\": [1, 1, 1], \"scale\": 3e38}")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["lights[0].radiance: the spectrum is not finite"],
    },
    Case {
        // Finite, but every sample that sees it is past what the film records.
        id: "radiance-past-the-film",
        edits: &[("\"radiance\": 1.0", "\"radiance\": 1e15")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["lights[0].radiance: must be at most 3.5184372e13 (2^45): the film takes one sample's colour up to 2^48, and a colour reaches 7.6 times the spectrum's largest value (max 1e15)"],
    },
    Case {
        // A light path leaving it carried 4 pi I: past f32 at 1e38, and
        // light tracing lost every path unreported.
        id: "intensity-past-f32",
        edits: &[("{\"type\": \"environment\", \"radiance\": 1.0}", "{\"type\": \"point\", \"position\": [0, 2, 0], \"intensity\": 1e38}")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["lights[0].intensity: must be at most 1.2676506e30 (2^100): a light path leaves a point light with 4 pi times it in its throughput"],
    },
    Case {
        id: "second-environment",
        edits: &[("{\"type\": \"environment\", \"radiance\": 1.0}", "{\"type\": \"environment\", \"radiance\": 1.0},\n    {\"type\": \"environment\", \"radiance\": 0.5}")],
        args: &[],
        out: "out.exr",
        position: "s.json:6:",
        words: &["lights[1]: a second environment light (lights[0] is one)"],
    },
    Case {
        id: "spectrum-type",
        edits: &[("\"reflectance\": 0.5", "\"reflectance\": [0.5]")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &[
            "materials.white.reflectance: invalid type: sequence, expected a number, a spectrum name, or an object with one of",
        ],
    },
    Case {
        id: "rgb-length",
        edits: &[("\"radiance\": 1.0", "\"radiance\": {\"rgb\": [1, 1, 1, 1]}")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["lights[0].radiance: \"rgb\": expected 3 numbers [r, g, b], got 4"],
    },
    Case {
        // Inside a tagged object (a shape): the error is at the value's own
        // line, 4, not at the object's closing brace on line 5.
        id: "tagged-field-type",
        edits: &[("\"radius\": 1}", "\"radius\": \"1\",\n \"subdivisions\": 2}")],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.radius: invalid type: string \"1\", expected f32"],
    },
    Case {
        id: "missing-field",
        edits: &[("\"fov\": 40, ", "")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera: missing field `fov`"],
    },
    Case {
        id: "unknown-type",
        edits: &[("\"type\": \"diffuse\"", "\"type\": \"plastic\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &["materials.white.type: unknown variant `plastic`", "dielectric"],
    },
    Case {
        id: "unknown-glass",
        edits: &[("\"materials\": {", "\"materials\": {\"glass\": {\"type\": \"dielectric\", \"ior\": \"BK8\"}, ")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &["materials.glass.ior: unknown spectrum \"BK8\"", "BK7"],
    },
    Case {
        id: "unknown-illuminant",
        edits: &[("\"radiance\": 1.0", "\"radiance\": \"D66\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["lights[0].radiance: unknown spectrum \"D66\"", "D65"],
    },
    Case {
        id: "unknown-metal",
        edits: &[("\"materials\": {", "\"materials\": {\"gold\": {\"type\": \"conductor\", \"metal\": \"Gold\"}, ")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &["materials.gold.metal: unknown metal \"Gold\" (known: Ag, Al, Au, Cu, CuZn)"],
    },
    Case {
        id: "duplicate-name",
        edits: &[("\"materials\": {", "\"materials\": {\"white\": {\"type\": \"mirror\"}, ")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &["materials", "duplicate name \"white\""],
    },
    Case {
        id: "scale-type",
        edits: &[("\"material\": \"white\"}", "\"material\": \"white\", \"transform\": {\"scale\": [1, 2]}}")],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].transform.scale: expected a number or [x, y, z]"],
    },
    Case {
        id: "empty-mesh-file",
        edits: &[("{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}", "{\"type\": \"obj\", \"file\": \"\"}")],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file: the file name is empty"],
    },
    Case {
        id: "missing-mesh",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"obj\", \"file\": \"nope.obj\"}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file: cannot read mesh", "nope.obj", "no such file"],
    },
    Case {
        id: "mesh-not-a-file",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"obj\", \"file\": \".\"}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file: cannot read mesh", "not a regular file"],
    },
    Case {
        id: "obj-partial-normals",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"obj\", \"file\": \"mixed.obj\"}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file:", "mixed.obj: object \"unnamed_object\" has normals on only some faces"],
    },
    Case {
        id: "obj-without-faces",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"obj\", \"file\": \"faceless.obj\"}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file:", "faceless.obj: no triangles"],
    },
    Case {
        id: "obj-lines-only",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"obj\", \"file\": \"lines.obj\"}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file:", "lines.obj: no triangles"],
    },
    Case {
        id: "obj-nan-normal",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"obj\", \"file\": \"nan-normal.obj\"}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.file:", "nan-normal.obj: non-finite vertex normal"],
    },
    Case {
        id: "triangle-too-large",
        edits: &[("\"material\": \"white\"}", "\"material\": \"white\", \"transform\": {\"scale\": 1e12}}")],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].transform: triangle ", " is too large for f32 arithmetic"],
    },
    Case {
        id: "duplicate-spectrum-key",
        edits: &[("\"radiance\": 1.0", "\"radiance\": {\"rgb\": [1, 1, 1], \"rgb\": [0, 0, 0]}")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        // (A light is an internally tagged enum: the path stops at it; the
        // position is the spectrum's.)
        words: &["lights[0].radiance: duplicate name \"rgb\""],
    },
    Case {
        id: "duplicate-material-override",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"gltf\", \"file\": \"nope.gltf\", \"materials\": {\"#0\": \"white\", \"#0\": \"white\"}}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.materials: duplicate name \"#0\""],
    },
    Case {
        id: "index-out-of-range",
        edits: &[(
            "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1}",
            "{\"type\": \"mesh\", \"positions\": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], \"indices\": [[0, 1, 7]]}",
        )],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[0].shape.indices: index 7 is out of range (3 positions)"],
    },
    Case {
        id: "reflectance-above-1",
        edits: &[("\"reflectance\": 0.5", "\"reflectance\": 1.5")],
        args: &[],
        out: "out.exr",
        position: "s.json:3:",
        words: &["materials.white.reflectance: a reflectance must not exceed 1"],
    },
    Case {
        id: "zero-up",
        edits: &[("\"look_at\": [0, 0, 0],", "\"look_at\": [0, 0, 0], \"up\": [0, 0, 0],")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.up: up must not be zero"],
    },
    Case {
        id: "degenerate-camera",
        edits: &[("\"look_at\": [0, 0, 0]", "\"look_at\": [0, 0, -3]")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.look_at: look_at must differ from position"],
    },
    Case {
        id: "fov-out-of-range",
        edits: &[("\"fov\": 40", "\"fov\": 180")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.fov: fov must be between 0 and 180 degrees"],
    },
    Case {
        id: "fov-too-small",
        edits: &[("\"fov\": 40", "\"fov\": 1e-40")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.fov: fov 1e-40 is too small"],
    },
    Case {
        id: "negative-spp-in-scene",
        edits: &[("\"lights\"", "\"render\": {\"spp\": -1},\n  \"lights\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["render.spp: invalid value: integer `-1`, expected u32"],
    },
    Case {
        id: "zero-spp-in-scene",
        edits: &[("\"lights\"", "\"render\": {\"spp\": 0},\n  \"lights\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["render.spp: spp must be at least 1"],
    },
    Case {
        // 2^64: serde_json reads an integer beyond u64 as a float, and the
        // message was "invalid type: floating point".
        id: "seed-beyond-u64",
        edits: &[("\"lights\"", "\"render\": {\"seed\": 18446744073709551616},\n  \"lights\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["render.seed: seed must be an integer in 0..=18446744073709551615, got 1.8446744073709552e19"],
    },
    Case {
        id: "negative-seed",
        edits: &[("\"lights\"", "\"render\": {\"seed\": -1},\n  \"lights\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["render.seed: seed must be an integer in 0..=18446744073709551615, got -1"],
    },
    Case {
        id: "fractional-seed",
        edits: &[("\"lights\"", "\"render\": {\"seed\": 1.5},\n  \"lights\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["render.seed: seed must be an integer in 0..=18446744073709551615, got 1.5"],
    },
    Case {
        id: "negative-spp-flag",
        edits: &[],
        args: &["--spp=-1"],
        out: "out.exr",
        position: "",
        words: &["invalid value '-1' for '--spp <SPP>'"],
    },
    Case {
        // clap takes a separate "-1" for a flag: the message does not name
        // --spp (and its tip, `-- -1`, would not help). Documented as is.
        id: "negative-spp-flag-spaced",
        edits: &[],
        args: &["--spp", "-1"],
        out: "out.exr",
        position: "",
        words: &["unexpected argument '-1' found"],
    },
    Case {
        id: "zero-spp-flag",
        edits: &[],
        args: &["--spp", "0"],
        out: "out.exr",
        position: "",
        words: &["--spp must be at least 1"],
    },
    Case {
        id: "output-not-writable",
        edits: &[],
        args: &[],
        out: "/proc/prism-bad-input.exr",
        position: "",
        words: &["cannot write /proc/prism-bad-input.exr: directory is not writable"],
    },
    Case {
        // The temporary file written first is named `.NAME.PID.tmp.exr`:
        // past 255 bytes it failed only once the render was done.
        id: "output-name-too-long",
        edits: &[],
        args: &[],
        out: LONG_NAME,
        position: "",
        words: &["its name is too long (the temporary file written beside it first would have a name of"],
    },
    Case {
        id: "output-is-a-directory",
        edits: &[],
        args: &[],
        out: "taken.exr",
        position: "",
        words: &["taken.exr: it is a directory"],
    },
    Case {
        id: "output-not-exr",
        edits: &[],
        args: &[],
        out: "out.png",
        position: "",
        words: &["--out must name an .exr file, got", "out.png"],
    },
    Case {
        id: "preview-not-writable",
        edits: &[],
        args: &["--png", "/no/such/dir/preview.png"],
        out: "out.exr",
        position: "",
        words: &["cannot write /no/such/dir/preview.png: directory /no/such/dir does not exist"],
    },
    Case {
        id: "unknown-integrator-in-scene",
        edits: &[("\"lights\"", "\"render\": {\"integrator\": \"magic\"},\n  \"lights\"")],
        args: &[],
        out: "out.exr",
        position: "s.json:5:",
        words: &["render.integrator: unknown integrator \"magic\" (valid: simple_path, path, light, bdpt)"],
    },
    Case {
        id: "image-too-large",
        edits: &[("\"width\": 8, \"height\": 8", "\"width\": 100000, \"height\": 100000")],
        args: &[],
        out: "out.exr",
        position: "s.json:2:",
        words: &["camera.width: 100000 x 100000 = 10000000000 pixels is more than the 134217728"],
    },
    Case {
        id: "image-too-large-flag",
        edits: &[],
        args: &["--width", "4294967295", "--height", "4294967295"],
        out: "out.exr",
        position: "",
        words: &["--width, --height: 4294967295 x 4294967295", "pixels is more than the 134217728"],
    },
    Case {
        // A field of view whose image has an area at 8 x 8 (the loader checks
        // it) but none, in f32, once 16384 times narrower.
        id: "no-image-area-flag",
        edits: &[("\"fov\": 40", "\"fov\": 1.2e-16")],
        args: &["--width", "1", "--height", "16384"],
        out: "out.exr",
        position: "",
        words: &["--width, --height: 1 x 16384: the image has no area at this aspect ratio (the field of view is too small)"],
    },
    Case {
        // 26 spheres of 5,242,880 triangles: the 26th crosses 2^27.
        id: "too-many-triangles",
        edits: &[("\"objects\": [", concat!("\"objects\": [", five_spheres!(), five_spheres!(), five_spheres!(), five_spheres!(), five_spheres!(), sphere9!()))],
        args: &[],
        out: "out.exr",
        position: "s.json:4:",
        words: &["objects[25].shape: the scene would hold 136314880 triangles, more than the 134217728 (2^27) prism builds"],
    },
    Case {
        id: "checkpoint-every-too-large",
        edits: &[],
        args: &["--checkpoint-every", "1e30"],
        out: "out.exr",
        position: "",
        words: &["--checkpoint-every must be a number of seconds >= 0 (below 2^64)"],
    },
    Case {
        id: "exposure-not-finite",
        edits: &[],
        args: &["--exposure=nan", "--png", "{dir}/preview.png"],
        out: "out.exr",
        position: "",
        words: &["--exposure must be a number of stops in [-126, 128), got NaN"],
    },
    Case {
        // The exposure is the PNG preview's: without one it was ignored.
        id: "exposure-without-png",
        edits: &[],
        args: &["--exposure", "5"],
        out: "out.exr",
        position: "",
        words: &["the following required arguments were not provided"],
    },
    Case {
        id: "exposure-overflow",
        edits: &[],
        args: &["--exposure", "130", "--png", "{dir}/preview.png"],
        out: "out.exr",
        position: "",
        words: &["--exposure must be a number of stops in [-126, 128), got 130"],
    },
    Case {
        id: "sidecar-is-a-directory",
        edits: &[],
        args: &[],
        out: "taken-sidecar.exr",
        position: "",
        words: &["taken-sidecar.json: it is a directory"],
    },
    Case {
        id: "stale-part-state",
        edits: &[],
        args: &[],
        out: "part.exr",
        position: "",
        words: &["part.state holds the samples of a part or a merge", "would leave it stale", "--sample-range A..B"],
    },
    Case {
        id: "output-replaces-checkpoint",
        edits: &[],
        args: &["--resume", "{dir}/part.png", "--png", "{dir}/part.png"],
        out: "out.exr",
        position: "",
        words: &["--png", "would replace the checkpoint (--resume)"],
    },
    Case {
        id: "png-extension",
        edits: &[],
        args: &["--png", "{dir}/mesh.obj"],
        out: "out.exr",
        position: "",
        words: &["--png must name a .png file, got", "mesh.obj"],
    },
    Case {
        id: "too-many-threads",
        edits: &[],
        args: &["--threads", "100000"],
        out: "out.exr",
        position: "",
        words: &["--threads 100000: at most 1024"],
    },
    Case {
        id: "passes-beyond-memory",
        edits: &[],
        args: &["--passes", "4294967295"],
        out: "out.exr",
        position: "",
        words: &["--passes: 4294967295 passes of 8x8 pixels are held in memory together"],
    },
];

/// An output name of 244 bytes: under the file system's 255, not with the
/// temporary file's `.` and `.PID.tmp.exr`.
const LONG_NAME: &str = concat!(
    "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa",
    "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa.exr"
);

/// As the `to` of an edit: cut the text where `from` starts.
const TRUNCATE: &str = "\0truncate";

const PREVIOUS: &[u8] = b"previous contents";

/// An earlier render's sidecar, which a render may replace (not any JSON).
const PREVIOUS_SIDECAR: &[u8] = br#"{"scene": "s.json", "integrator": "path", "spp": 1}"#;

const MIXED_OBJ: &str = "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvn 0 1 0\nf 1//1 2//1 3//1\nf 1 3 4\n";

/// Runs one case; returns a description of what went wrong, if anything.
fn run(case: &Case) -> Result<(), String> {
    let dir = temp_dir(case.id);
    let mut text = scenes::TINY_SCENE.to_string();
    for (from, to) in case.edits {
        if !text.contains(from) {
            return Err(format!("edit {from:?} does not apply"));
        }
        text = if *to == TRUNCATE { text[..text.find(from).unwrap()].to_string() } else { text.replacen(from, to, 1) };
    }
    std::fs::write(dir.join("s.json"), &text).unwrap();
    std::fs::create_dir_all(dir.join("taken.exr")).unwrap();
    std::fs::create_dir_all(dir.join("taken-sidecar.json")).unwrap();
    // An OBJ with normals on one face of two (tobj then gives 3 normals for 6 vertices).
    std::fs::write(dir.join("mixed.obj"), MIXED_OBJ).unwrap();
    // An OBJ with vertices but no face.
    std::fs::write(dir.join("faceless.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
    // Faces of one and two vertices and a line: no area (tobj padded them
    // into zero-area triangles).
    std::fs::write(dir.join("lines.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1\nf 1 2\nl 2 3\n").unwrap();
    // A triangle whose first vertex normal is NaN.
    std::fs::write(dir.join("nan-normal.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn nan 0 1\nvn 0 0 1\nf 1//1 2//2 3//2\n")
        .unwrap();
    // An earlier part's state (its contents are never read by these cases).
    std::fs::write(dir.join("part.state"), PREVIOUS).unwrap();
    let out = if Path::new(case.out).is_absolute() { PathBuf::from(case.out) } else { dir.join(case.out) };
    // An existing output and sidecar, which a failure must not touch.
    let sidecar = out.with_extension("json");
    let keep = out.parent().is_some_and(|p| p == dir) && !case.out.starts_with("taken");
    if keep {
        std::fs::write(&out, PREVIOUS).unwrap();
        std::fs::write(&sidecar, PREVIOUS_SIDECAR).unwrap();
    }
    let o = Command::new(env!("CARGO_BIN_EXE_prism"))
        .arg("render")
        .arg(dir.join("s.json"))
        .arg("--out")
        .arg(&out)
        .args(case.args.iter().map(|a| a.replace("{dir}", &dir.display().to_string())))
        .arg("--quiet")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    let mut problems = Vec::new();
    if o.status.success() {
        problems.push("exit status 0".to_string());
    }
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    if errors.len() != 1 {
        problems.push(format!("{} error lines", errors.len()));
    }
    let line = errors.first().copied().unwrap_or_default();
    if !case.position.is_empty() && !line.contains(&format!("{}{}", dir.join("").display(), case.position)) {
        problems.push(format!("no {:?} position", case.position));
    }
    for w in case.words {
        if !line.contains(w) {
            problems.push(format!("missing {w:?}"));
        }
    }
    if keep {
        if std::fs::read(&out).ok().as_deref() != Some(PREVIOUS)
            || std::fs::read(&sidecar).ok().as_deref() != Some(PREVIOUS_SIDECAR)
        {
            problems.push("the existing output or sidecar changed".to_string());
        }
    } else if case.out != "taken.exr" && out.exists() {
        problems.push("an output file was written".to_string());
    }
    if std::fs::read(dir.join("part.state")).ok().as_deref() != Some(PREVIOUS) {
        problems.push("the earlier part's state changed".to_string());
    }
    if dir.join("preview.png").exists() {
        problems.push("a PNG was written".to_string());
    }
    let leftovers: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with('.'))
        .collect();
    if !leftovers.is_empty() {
        problems.push(format!("temporary files left: {leftovers:?}"));
    }
    let _ = std::fs::remove_dir_all(&dir);
    if problems.is_empty() {
        eprintln!("{:<24} {line}", case.id);
        Ok(())
    } else {
        Err(format!("{}: {}\n  stderr: {stderr}", case.id, problems.join("; ")))
    }
}

#[test]
fn every_bad_input_gives_one_clear_error_and_keeps_existing_output() {
    let failures: Vec<String> = CASES.iter().filter_map(|c| run(c).err()).collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The same scene without the fault renders (each case fails for the
/// reason it names, not because the base scene or command is broken).
#[test]
fn the_base_case_succeeds() {
    let dir = temp_dir("base");
    std::fs::write(dir.join("s.json"), scenes::TINY_SCENE).unwrap();
    let out = dir.join("out.exr");
    std::fs::write(&out, PREVIOUS).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_prism"))
        .arg("render")
        .arg(dir.join("s.json"))
        .arg("--out")
        .arg(&out)
        .args(["--spp", "1", "--quiet", "--png"])
        .arg(dir.join("preview.png"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_ne!(std::fs::read(&out).unwrap(), PREVIOUS, "a successful render replaces the output");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every row of the Errors table in docs/scene-format.md names a case of
/// this file or a test of tests/cli.rs, and every case here has a row.
#[test]
fn error_table_matches_the_tests() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(root.join("docs/scene-format.md")).unwrap();
    let cli = std::fs::read_to_string(root.join("tests/cli.rs")).unwrap();
    let section = &doc[doc.find("\n## Errors").expect("docs/scene-format.md has an Errors section") + 1..];
    let section = &section[..section.find("\n## ").unwrap_or(section.len())];
    let mut rows = Vec::new();
    for line in section.lines().filter(|l| l.starts_with("| `")) {
        let cols: Vec<&str> = line.split(" | ").collect();
        let id = cols[0].trim_start_matches("| `").split('`').next().unwrap();
        let test = cols.last().unwrap().trim_end_matches('|').trim().trim_matches('`');
        rows.push(id.to_string());
        if let Some(f) = test.strip_prefix("cli.rs: ") {
            assert!(cli.contains(&format!("fn {f}(")), "row {id}: tests/cli.rs has no test {f}");
        } else {
            assert_eq!(test, "bad_input.rs", "row {id}: unknown test column {test:?}");
            assert!(CASES.iter().any(|c| c.id == id), "row {id}: no case in tests/bad_input.rs");
        }
    }
    for c in CASES {
        assert!(rows.iter().any(|r| r == c.id), "case {} has no row in the Errors table", c.id);
    }
    assert!(rows.len() >= CASES.len() + 8, "the table should also list the cases tested in tests/cli.rs");
}

/// A UTF-8 byte order mark before the scene is skipped (it was "1:1:
/// expected value"), and positions on the first line stay the columns an
/// editor shows. Control: the same text with any other character first
/// is an error.
#[test]
fn a_byte_order_mark_is_skipped() {
    let parse = |text: &str| prism::scene::parse_scene(text, "s.json", Path::new("."));
    assert!(parse(&format!("\u{feff}{}", scenes::TINY_SCENE)).is_ok());
    let bad_first_line = r#"{"camera": 1}"#;
    let plain = parse(bad_first_line).err().unwrap().to_string();
    let marked = parse(&format!("\u{feff}{bad_first_line}")).err().unwrap().to_string();
    assert!(plain.starts_with("s.json:1:"), "{plain}");
    assert_eq!(marked, plain);
    assert!(parse(&format!("\u{200b}{}", scenes::TINY_SCENE)).is_err());
}

/// The control of `spectrum-cycle`: a chain of names that ends is no cycle,
/// however long (one of more than 9 names was "refers to itself"), and it
/// resolves to the value at its end (a review, session 55: only that it
/// parsed was checked).
#[test]
fn a_long_chain_of_spectrum_names_resolves() {
    let links: Vec<String> = (0..20).map(|i| format!("\"s{i}\": \"s{}\"", i + 1)).collect();
    let spectra = format!("\"spectra\": {{{}, \"s20\": 0.25}},\n  \"materials\"", links.join(", "));
    let text = scenes::TINY_SCENE
        .replace("\"materials\"", &spectra)
        .replace("\"reflectance\": 0.5", "\"reflectance\": \"s0\"");
    let scene = prism::scene::parse_scene(&text, "s.json", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build();
    let prism::materials::Bsdf::Diffuse(d) = scene.materials[0].bsdf() else { panic!("not diffuse") };
    for l in [400.0, 550.0, 700.0] {
        assert_eq!(d.reflectance.eval(l), 0.25, "{l} nm");
    }
}
