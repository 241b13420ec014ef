#[path = "common/scenes.rs"]
mod scenes;
use glam::Vec3A;
use prism::camera::Camera;
use prism::materials::{Bsdf, Diffuse};
use prism::scene::SceneBuilder;
use prism::shapes::Mesh;
use prism::spectrum::Spectrum;
use prism::stats::render_passes;
use scenes::integrator;

#[test]
fn dbg() {
    let camera = Camera::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Y, 70.0, 32, 32);
    let mut b = SceneBuilder::new(camera);
    let black = b.material("black", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.0))));
    let mut sphere = Mesh::sphere(Vec3A::new(0.1, -0.05, 0.2), 2.0, 3, false);
    sphere.flip();
    b.mesh("sphere", sphere, black, Some((Spectrum::Constant(1.0), false)));
    let s = b.build();
    for name in ["light", "path"] {
        let passes = render_passes(&s, integrator(name).as_ref(), 64, 32, 5000, 0);
        // luminance per ring of radius (pixels from centre), and per pass
        let nr = 4;
        let mut per = vec![vec![0f64; nr]; passes.len()];
        let mut cnt = vec![0f64; nr];
        for j in 0..32 { for i in 0..32 {
            let r = (((i as f32 + 0.5 - 16.0).powi(2) + (j as f32 + 0.5 - 16.0).powi(2)).sqrt() / 22.7 * nr as f32) as usize;
            let r = r.min(nr-1);
            cnt[r] += 1.0;
            for (k, p) in passes.iter().enumerate() { let px = p[j*32+i]; per[k][r] += (0.212639*px[0]+0.715169*px[1]+0.072192*px[2]) as f64; }
        }}
        for r in 0..nr {
            let v: Vec<f64> = per.iter().map(|p| p[r] / cnt[r]).collect();
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let sd = (v.iter().map(|x| (x-m).powi(2)).sum::<f64>() / (v.len()-1) as f64).sqrt() / (v.len() as f64).sqrt();
            eprintln!("{name} ring {r}: Y = {m:.5} +- {sd:.5}  (z = {:.2})", (m-1.0)/sd);
        }
    }
}
