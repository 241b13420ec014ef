use glam::Vec3A;
use prism::geometry::Ray;
use std::path::Path;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let scene = prism::scene::load_scene(Path::new(&a[1])).unwrap().build();
    let bytes = std::fs::read(&a[2]).unwrap();
    let f: Vec<f32> = bytes.chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    let rays: Vec<Ray> =
        f.chunks(6).map(|c| Ray::new(Vec3A::new(c[0], c[1], c[2]), Vec3A::new(c[3], c[4], c[5]))).collect();
    let reps: usize = a[3].parse().unwrap();
    let t = std::time::Instant::now();
    let mut n = 0;
    for _ in 0..reps {
        n += rays.iter().filter(|r| std::hint::black_box(scene.accel.intersect(r, f32::INFINITY)).is_some()).count();
    }
    eprintln!(
        "{} rays x {reps}: {n} hits, {:.1} ns/ray",
        rays.len(),
        t.elapsed().as_secs_f64() * 1e9 / (rays.len() * reps) as f64
    );
}
