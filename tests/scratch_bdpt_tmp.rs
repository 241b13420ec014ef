#[path = "common/scenes.rs"]
mod scenes;
use glam::Vec3A;
use prism::camera::Camera;
use prism::materials::{Bsdf, Diffuse};
use prism::scene::SceneBuilder;
use prism::shapes::Mesh;
use prism::spectrum::Spectrum;
use prism::stats::{render_passes, BlockStats, compare_to_value};
use scenes::{integrator, srgb_of};

#[test]
fn dbg() {
    let camera = Camera::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Y, 70.0, 32, 32);
    let mut b = SceneBuilder::new(camera);
    let black = b.material("black", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.0))));
    let mut sphere = Mesh::sphere(Vec3A::new(0.1, -0.05, 0.2), 2.0, 3, false);
    sphere.flip();
    b.mesh("sphere", sphere, black, Some((Spectrum::Constant(1.0), false)));
    let s = b.build();
    let e = srgb_of(&Spectrum::Constant(1.0));
    eprintln!("expected {e:?}");
    for name in ["path", "light"] {
        let st = BlockStats::from_passes(&render_passes(&s, integrator(name).as_ref(), 64, 16, 10, 0), 32, 32, 8);
        eprintln!("{name} {}", compare_to_value(&st, e));
        for by in 0..4 { let row: Vec<String> = (0..4).map(|bx| { let m = st.mean[by*4+bx]; format!("{:.3}/{:.3}/{:.3}", m[0], m[1], m[2]) }).collect(); eprintln!("  {}", row.join("  ")); }
    }
}
