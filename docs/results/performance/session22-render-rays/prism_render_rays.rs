// Scratch program of session 22 (docs/performance-log.md, "Session 22"), kept as a record, not built:
// a Cargo project with `prism = { path = "<repo>" }`, glam and rayon as dependencies; its argument is the ray log.
// prism's ray queries on the rays a `path` render traced (logged by a scratch build):
// kind 0 bounce closest hits, 1 shadow rays, 2 camera rays (8 per pixel, traced as packets in the render).
use glam::Vec3A;
use prism::accel::LANES;
use prism::geometry::Ray;
use std::hint::black_box;
use std::time::Instant;

fn best<F: Fn() -> usize>(f: F) -> (f64, usize) {
    let mut b = f64::MAX;
    let mut n = 0;
    for _ in 0..7 {
        let t = Instant::now();
        n = f();
        b = b.min(t.elapsed().as_secs_f64());
    }
    (b, n)
}

fn main() {
    let path = std::env::args().nth(1).unwrap();
    let scene = prism::scene::load_scene(std::path::Path::new("/work/main/scenes/cornell-box.json")).unwrap().build();
    let bytes = std::fs::read(&path).unwrap();
    let f: Vec<f32> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    let mut kinds: [Vec<(Ray, f32)>; 3] = Default::default();
    for r in f.chunks_exact(10) {
        let ray = Ray { o: Vec3A::new(r[1], r[2], r[3]), d: Vec3A::new(r[4], r[5], r[6]), skip: [r[8].to_bits(), r[9].to_bits()] };
        kinds[r[0] as usize].push((ray, r[7]));
    }
    let accel = &scene.accel;
    let ns = |t: f64, n: usize| t / n as f64 * 1e9;
    for (k, name) in [(0, "bounce"), (2, "camera")] {
        let rays = &kinds[k];
        let (t, h) = best(|| rays.iter().filter(|(r, _)| black_box(accel.intersect(r, f32::INFINITY)).is_some()).count());
        let (tsi, _) = best(|| rays.iter().filter(|(r, _)| black_box(scene.intersect(r)).is_some()).count());
        let sum_t: f64 = rays.iter().filter_map(|(r, _)| accel.intersect(r, f32::INFINITY)).map(|h| h.t as f64).sum();
        print!("{name}: {} rays, hit {:.4}, mean hit t {:.4}, {:.1} ns/ray, with surface interaction {:.1} ns", rays.len(), h as f64 / rays.len() as f64, sum_t / h as f64, ns(t, rays.len()), ns(tsi, rays.len()));
        if k == 2 {
            let packets: Vec<[Ray; LANES]> = rays.chunks_exact(LANES).map(|c| std::array::from_fn(|l| c[l].0)).collect();
            let (tp, hp) = best(|| packets.iter().map(|p| black_box(accel.intersect8(p, [f32::INFINITY; LANES], 0xff)).iter().filter(|h| h.is_some()).count()).sum());
            print!("; in packets of 8: {:.1} ns/ray (hit {:.4})", ns(tp, rays.len()), hp as f64 / rays.len() as f64);
        }
        println!();
    }
    let rays = &kinds[1];
    let (t, h) = best(|| rays.iter().filter(|(r, tm)| accel.occluded(r, *tm)).count());
    println!("shadow: {} rays, occluded {:.4}, {:.1} ns/ray", rays.len(), h as f64 / rays.len() as f64, ns(t, rays.len()));
}
