//! Any bytes, read as a scene file (lossy UTF-8): `parse_scene` returns Ok or
//! Err and `build()` of an Ok scene returns; a panic is a crash. Mesh files
//! resolve against fuzz/meshes (tri.obj).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes");
    if let Ok(builder) = prism::scene::parse_scene(&text, "fuzz.json", &dir) {
        let scene = builder.build();
        std::hint::black_box(scene.triangle_count());
    }
});
