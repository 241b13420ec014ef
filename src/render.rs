//! The parallel driver: tasks over rayon, a progress bar, deterministic
//! seeding and a deterministic merge.
//!
//! Determinism: every sample (pixel, index) draws from its own stream seeded
//! by (seed, pixel, index), light tracing's light paths included (one per
//! (pixel, index), whatever pixel it splats into), so sample index ranges
//! split camera and light paths alike. The film adds exact fixed-point sums
//! (film.rs), so no result depends on which thread ran what, nor on how the
//! sample indices were split into chunks, checkpoints or parts: the same
//! scene, seed and samples give bit-identical images at any thread count.
//! (One caveat: a pixel sum that would leave the fixed-point range is
//! dropped and counted, and which addend overflows depends on the grouping
//! of the adds; the grouping depends on the image and sample range, not on
//! the threads.)
//! The work is cut into tasks, a tile and a run of sample indices each
//! (`Tasks`), merged in task order (`TaskQueue`), for the f64 per-strategy
//! images (strategies.rs).

use crate::accel::LANES;
use crate::film::{add_fixed, to_fixed, DroppedSamples, Film};
use crate::integrators::Integrator;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::{SampledCmf, SampledSpectrum, SampledWavelengths};
use crate::strategies::{StrategyImages, StrategyRecord, TaskStrategies};
use glam::{UVec2, Vec2, Vec3, Vec4};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::ThreadPool;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::ops::Range;
use std::rc::Rc;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

const TILE: u32 = 16;
/// A render is cut into at least this many tasks, small images included
/// (`Tasks`).
const MIN_TASKS: usize = 64;

/// A contribution to the pixel that contains `raster` (box filter), from any
/// sample of the image (light tracing, BDPT's t = 1 strategy).
#[derive(Clone, Copy, Debug)]
pub struct Splat {
    pub raster: Vec2,
    pub l: SampledSpectrum,
}

/// Per-worker scratch memory, reused from sample to sample so the hot loop
/// does not allocate.
#[derive(Default)]
pub struct Workspace {
    /// Splats of the current sample, converted to colour when it finishes
    /// (with its final wavelengths, in case a dispersive event terminated the
    /// secondaries after the splat was made).
    pub splats: Vec<Splat>,
    pub paths: crate::path::PathScratch,
    /// Per-strategy records of the current sample; `Some` only when
    /// per-strategy images are being made (`render_with_strategies`).
    pub strategies: Option<Vec<StrategyRecord>>,
    /// The random streams and wavelengths of the samples being taken
    /// together (`Integrator::sample_lanes`).
    pub samplers: Vec<Sampler>,
    pub lambdas: Vec<SampledWavelengths>,
}

#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub seed: u64,
    /// Worker threads; 0 = one per core.
    pub threads: usize,
    pub progress: bool,
}

#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub wall: Duration,
    pub samples: u64,
    pub rays: u64,
    /// Worker threads of the render's pool (`RenderOptions::threads`
    /// resolved: 0 is one per core).
    pub threads: usize,
}

impl RenderStats {
    pub fn add(&mut self, o: &RenderStats) {
        self.wall += o.wall;
        self.samples += o.samples;
        self.rays += o.rays;
        self.threads = self.threads.max(o.threads);
    }
}

struct TaskOutput {
    origin: UVec2,
    size: UVec2,
    /// Samples per pixel in it.
    spp: u64,
    sums: Vec<[i128; 3]>,
    /// (pixel index, colour): kept as f32 until the merge, the most compact
    /// form (the tasks awaiting their merge may hold many splats).
    splats: Vec<(u32, Vec3)>,
    dropped: DroppedSamples,
    rays: u64,
    strategies: Option<TaskStrategies>,
}

/// Adds samples `samples` (indices) of every pixel to the film.
pub fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    opts: &RenderOptions,
    film: &mut Film,
    samples: Range<u32>,
) -> RenderStats {
    let bar = progress_bar(opts.progress, film, &samples);
    let stats = render_impl(scene, integrator, &thread_pool(opts), &bar, opts.seed, film, samples, None);
    bar.finish_and_clear();
    stats
}

/// `render` in consecutive chunks of `chunk` sample indices, calling
/// `after_chunk` with the film after each one (where checkpoints are taken).
/// The film's sums are exact, so the image does not depend on `chunk`.
pub fn render_chunked(
    scene: &Scene,
    integrator: &dyn Integrator,
    opts: &RenderOptions,
    film: &mut Film,
    samples: Range<u32>,
    chunk: u32,
    mut after_chunk: impl FnMut(&Film) -> anyhow::Result<()>,
) -> anyhow::Result<RenderStats> {
    assert!(chunk > 0, "chunks of zero samples");
    let pool = thread_pool(opts);
    // The chunks are made as they come: a list of them all would take 8
    // bytes per chunk, 32 GiB for 2^32 one-sample chunks.
    let bar = progress_bar(opts.progress, film, &samples);
    let mut total = RenderStats::default();
    for first in samples.clone().step_by(chunk as usize) {
        let c = first..first.saturating_add(chunk).min(samples.end);
        total.add(&render_impl(scene, integrator, &pool, &bar, opts.seed, film, c, None));
        after_chunk(film)?;
    }
    bar.finish_and_clear();
    Ok(total)
}

/// `render`, also adding each connection strategy's contribution to
/// `strategies` (for integrators that record them: BDPT). The film gets
/// exactly what `render` would give it.
pub fn render_with_strategies(
    scene: &Scene,
    integrator: &dyn Integrator,
    opts: &RenderOptions,
    film: &mut Film,
    samples: Range<u32>,
    strategies: &mut StrategyImages,
) -> RenderStats {
    assert_eq!(
        (strategies.width, strategies.height),
        (film.width, film.height),
        "strategy images and film differ in size"
    );
    let bar = progress_bar(opts.progress, film, &samples);
    let pool = thread_pool(opts);
    let stats = render_impl(scene, integrator, &pool, &bar, opts.seed, film, samples, Some(strategies));
    bar.finish_and_clear();
    stats
}

/// The most worker threads a render may ask for: each has its own stack
/// and workspace, and the OS refuses far fewer than `usize::MAX` (the
/// library panics when it cannot start the pool; the commands check first).
pub const MAX_THREADS: usize = 1024;

/// A command-line thread count: 0 (all cores) to `MAX_THREADS`, and as
/// many threads as the process may start (a memory or process limit can
/// refuse them): a pool is started once here, so that a limit is an error
/// before the render rather than a panic in it. Its threads have exited
/// when this returns (a dropped pool's end on their own time), so the
/// render's pool does not count against the limit beside them.
pub fn check_threads(threads: usize) -> anyhow::Result<()> {
    anyhow::ensure!(threads <= MAX_THREADS, "--threads {threads}: at most {MAX_THREADS} (0 = all cores)");
    let exited = std::sync::Arc::new((std::sync::Mutex::new(0usize), std::sync::Condvar::new()));
    let on_exit = exited.clone();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .exit_handler(move |_| {
            let (count, changed) = &*on_exit;
            *count.lock().unwrap_or_else(|e| e.into_inner()) += 1;
            changed.notify_all();
        })
        .spawn_handler(spawn_when_the_last_has_started)
        .build()
        .map_err(|e| anyhow::anyhow!("--threads {threads}: cannot start the worker threads: {e}"))?;
    let started = pool.current_num_threads();
    drop(pool);
    let (count, changed) = &*exited;
    let count = count.lock().unwrap_or_else(|e| e.into_inner());
    drop(changed.wait_while(count, |n| *n < started).unwrap_or_else(|e| e.into_inner()));
    Ok(())
}

/// Starts a pool thread once the one before it has started, with room
/// left for its signal stack. A thread's start maps its stack in the
/// spawning thread, then its signal stack in itself (std's stack-overflow
/// handler), and a failure there aborts the process. Spawned all at once,
/// threads not yet started could find the rest of an address-space limit
/// taken by later threads' stacks: `--threads 1024` under `ulimit -v`
/// aborted for 21 of 237 limits from 1.30 to 1.56 GB (a seed sweep's
/// `threads_the_process_cannot_start_are_an_error`, session 48). One at a
/// time, a stack that left less than the signal stack needs still did,
/// at fixed limits (2 of the 237, one of them in 20 runs of 20): so
/// `HEADROOM` is held while the stack is mapped and freed before the
/// thread maps its signal stack. With it, 1 run of 1,443 over such limits
/// (two scenes) did not end with the error, and that one did not again.
fn spawn_when_the_last_has_started(thread: rayon::ThreadBuilder) -> std::io::Result<()> {
    let mut headroom = Vec::<u8>::new();
    headroom.try_reserve_exact(HEADROOM).map_err(|_| std::io::Error::from(std::io::ErrorKind::OutOfMemory))?;
    let mut builder = std::thread::Builder::new();
    if let Some(name) = thread.name() {
        builder = builder.name(name.to_owned());
    }
    if let Some(size) = thread.stack_size() {
        builder = builder.stack_size(size);
    }
    let (started, wait) = std::sync::mpsc::channel();
    let spawned = builder.spawn(move || {
        let _ = started.send(());
        thread.run()
    });
    drop(headroom);
    spawned?;
    let _ = wait.recv();
    Ok(())
}

/// Address space held while a pool thread's stack is mapped, for its
/// signal stack (a few pages) and more. Above glibc's largest dynamic mmap
/// threshold (32 MiB on 64-bit), so malloc maps it apart and free unmaps
/// it, whatever was allocated before; its pages are never touched.
const HEADROOM: usize = 33 << 20;

/// The calling thread's pool of `opts.threads` workers, made at its first
/// render and kept for the next: passes, checkpoint chunks and converge's
/// slices reuse it. A pool made per call left the last one's threads to
/// exit on their own time (rayon does not join them), and under a limit on
/// threads or address space the next pool could fail to start: a panic
/// after passes were rendered (from an audit, session 50). Kept per
/// calling thread, not per process, so that renders started at once from
/// several threads (tests) never share workers.
fn thread_pool(opts: &RenderOptions) -> Rc<ThreadPool> {
    thread_local! {
        static POOL: RefCell<Option<(usize, Rc<ThreadPool>)>> = const { RefCell::new(None) };
    }
    POOL.with_borrow_mut(|kept| match kept {
        Some((threads, pool)) if *threads == opts.threads => pool.clone(),
        _ => {
            *kept = None;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(opts.threads)
                .spawn_handler(spawn_when_the_last_has_started)
                .build()
                .expect("thread pool");
            kept.insert((opts.threads, Rc::new(pool))).1.clone()
        }
    })
}

/// The image's tiles (origin, size) in row-major order.
fn tile_grid(w: u32, h: u32) -> Vec<(UVec2, UVec2)> {
    (0..h.div_ceil(TILE))
        .flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx, ty)))
        .map(|(tx, ty)| {
            let o = UVec2::new(tx * TILE, ty * TILE);
            (o, UVec2::new(TILE.min(w - o.x), TILE.min(h - o.y)))
        })
        .collect()
}

/// A unit of the render's work: a tile's pixels, for a run of sample
/// indices.
#[derive(Debug)]
struct Task {
    origin: UVec2,
    size: UVec2,
    samples: Range<u32>,
}

/// The render's tasks, in merge order: each of the image's tiles in
/// row-major order with consecutive runs of `samples` (whole packets of
/// `LANES` samples). The runs are cut so that a small image keeps every
/// thread busy too (at least `MIN_TASKS` tasks: a 16 x 16 image is one tile,
/// which one thread rendered alone before), and so that no run is longer
/// than `MAX_RUN`. The cut depends on the image and the samples only, never
/// on the thread count, and the film's sums are exact, so it does not change
/// the image. The tasks are made as they are taken: a render of 2^32
/// samples a pixel has some 2^26 of them per tile.
struct Tasks {
    tiles: Vec<(UVec2, UVec2)>,
    samples: Range<u32>,
    /// Samples a pixel in a task (the last run of a tile may have fewer).
    run: u64,
    /// Tasks per tile.
    runs: usize,
}

/// The longest run of sample indices in one task. A task holds its splats
/// until it is merged, so its memory grows with its run: light tracing in a
/// 64 x 64 white room of albedo 0.99 (~70 splats a light path) took 85 KB a
/// sample of each pixel, 30 MB at 256 samples a pixel with 2 threads, and
/// would have taken gigabytes for a long render of an image of at least
/// `MIN_TASKS` tiles, whose tasks were once whole tiles with every sample
/// (an audit, session 44). 64, the benchmark's spp, leaves its tasks as
/// they were.
const MAX_RUN: u64 = 64;
const _: () = assert!(MAX_RUN >= LANES as u64 && MAX_RUN % LANES as u64 == 0, "runs are whole packets");

impl Tasks {
    fn new(width: u32, height: u32, samples: Range<u32>) -> Self {
        let tiles = tile_grid(width, height);
        let n = samples.len() as u64;
        let lanes = LANES as u64;
        let runs = (MIN_TASKS as u64).div_ceil(tiles.len().max(1) as u64).min(n.div_ceil(lanes)).max(1);
        let run = n.div_ceil(runs).next_multiple_of(lanes).clamp(lanes, MAX_RUN);
        let runs = if n == 0 { 0 } else { n.div_ceil(run) as usize };
        Self { tiles, samples, run, runs }
    }

    fn len(&self) -> usize {
        self.tiles.len() * self.runs
    }

    fn get(&self, i: usize) -> Task {
        let (origin, size) = self.tiles[i / self.runs];
        let first = self.samples.start as u64 + (i % self.runs) as u64 * self.run;
        let end = (first + self.run).min(self.samples.end as u64);
        Task { origin, size, samples: first as u32..end as u32 }
    }
}

#[allow(clippy::too_many_arguments)]
fn render_impl(
    scene: &Scene,
    integrator: &dyn Integrator,
    pool: &ThreadPool,
    bar: &ProgressBar,
    seed: u64,
    film: &mut Film,
    samples: Range<u32>,
    strategies: Option<&mut StrategyImages>,
) -> RenderStats {
    // With per-strategy images, their bound on the paths' length.
    let strategy_length = strategies.as_ref().map(|s| s.max_length);
    let start = Instant::now();
    let (w, h, spp) = (film.width, film.height, samples.len() as u64);
    let tasks = Tasks::new(w, h, samples);
    let merge = Merge { film, strategies, rays: 0, splats: Vec::new() };
    let queue = TaskQueue::new(tasks.len(), merge);
    pool.broadcast(|_| {
        let mut ws = Workspace { strategies: strategy_length.map(|_| Vec::new()), ..Workspace::default() };
        queue.work(|i| {
            let out = render_task(scene, integrator, seed, &mut ws, strategy_length, w, &tasks.get(i));
            bar.inc(out.sums.len() as u64 * out.spp);
            out
        });
    });
    let mut merge = queue.into_merge();
    merge.add_splats();
    let Merge { film, strategies, rays, .. } = merge;
    film.spp += spp;
    if let Some(images) = strategies {
        images.spp += spp;
    }
    RenderStats { wall: start.elapsed(), samples: spp * w as u64 * h as u64, rays, threads: pool.current_num_threads() }
}

/// Where finished tasks go: the film, the per-strategy images, the ray count.
struct Merge<'a> {
    film: &'a mut Film,
    strategies: Option<&'a mut StrategyImages>,
    rays: u64,
    /// Splats of merged tasks not yet in the film, in task order.
    splats: Vec<(u32, Vec3)>,
}

/// Splats held back before they are added to the film, at most (16 MiB).
const SPLAT_BATCH: usize = 1 << 20;

impl Merge<'_> {
    fn add(&mut self, mut out: TaskOutput) {
        self.rays += out.rays;
        if let (Some(images), Some(records)) = (self.strategies.as_deref_mut(), out.strategies.take()) {
            images.add_task(out.origin, out.size, records);
        }
        self.splats.append(&mut out.splats);
        merge_task(self.film, out);
        if self.splats.len() >= self.film.sums.len().min(SPLAT_BATCH) {
            self.add_splats();
        }
    }

    /// Adds the held splats to the film in pixel order, so that the adds
    /// stream through it. One task's splats (~28,000 for 16 x 16 pixels at
    /// 32 spp) land on scattered pixels of the whole film (48 bytes each,
    /// 3 MiB at 256 x 256), which had left the cache by the next merge:
    /// added one task at a time, even in pixel order, they cost `bdpt` 2.3 %
    /// of its time and `light` 7 %. Held until there are about as many as
    /// pixels, one pass over the film serves them all (docs/performance-log.md,
    /// "Session 18"). The order is a function of the tasks' order, so the
    /// film's drop decisions stay deterministic.
    fn add_splats(&mut self) {
        radsort::sort_by_key(&mut self.splats, |&(pixel, _)| pixel);
        for (i, rgb) in self.splats.drain(..) {
            if !add_fixed(&mut self.film.sums[i as usize], to_fixed(rgb)) {
                self.film.dropped.infinite += 1;
            }
        }
    }
}

/// Tasks handed out in order and merged in order, with no barrier: a worker
/// takes the next task as soon as it is free, and a finished task waits only
/// for the tasks before it. The merge order (task order) is what makes the
/// per-strategy f64 sums, and the film's drop decisions, independent of the
/// thread count. At most `WINDOW` tasks are taken but not yet merged, which
/// bounds the memory held by their splats. (Batches of tiles with a barrier
/// after each, as before, left a core idle at every barrier: 3 % of a Cornell
/// box render on 2 threads.)
struct TaskQueue<'a> {
    state: Mutex<QueueState<'a>>,
    merged: Condvar,
    len: usize,
}

struct QueueState<'a> {
    /// The next task to hand out.
    next: usize,
    /// Tasks before this one are in the merge.
    merged: usize,
    finished: BTreeMap<usize, TaskOutput>,
    merge: Merge<'a>,
    /// A worker panicked: the others stop taking tasks (and stop waiting
    /// for one that will never be merged).
    abandoned: bool,
}

/// Tasks taken but not yet merged, at most.
const WINDOW: usize = 64;

impl<'a> TaskQueue<'a> {
    fn new(len: usize, merge: Merge<'a>) -> Self {
        let state = QueueState { next: 0, merged: 0, finished: BTreeMap::new(), merge, abandoned: false };
        Self { state: Mutex::new(state), merged: Condvar::new(), len }
    }

    /// A worker's loop: renders tasks until none is left.
    fn work(&self, mut render: impl FnMut(usize) -> TaskOutput) {
        let _abandon = AbandonOnPanic(self);
        while let Some(i) = self.take() {
            let out = render(i);
            self.finish(i, out);
        }
    }

    /// The next task to render, once it is within `WINDOW` of the merge;
    /// `None` when all are taken.
    fn take(&self) -> Option<usize> {
        let mut st = self.lock();
        while st.next < self.len && st.next >= st.merged + WINDOW && !st.abandoned {
            st = self.merged.wait(st).unwrap_or_else(|e| e.into_inner());
        }
        (st.next < self.len && !st.abandoned).then(|| {
            st.next += 1;
            st.next - 1
        })
    }

    /// Task `i`'s output; merges every finished task that no earlier one
    /// still holds back.
    fn finish(&self, i: usize, out: TaskOutput) {
        let mut st = self.lock();
        st.finished.insert(i, out);
        loop {
            let next = st.merged;
            let Some(out) = st.finished.remove(&next) else { break };
            st.merge.add(out);
            st.merged += 1;
        }
        drop(st);
        self.merged.notify_all();
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, QueueState<'a>> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn into_merge(self) -> Merge<'a> {
        let st = self.state.into_inner().unwrap_or_else(|e| e.into_inner());
        assert!(!st.abandoned && st.merged == self.len, "{} of {} tasks merged", st.merged, self.len);
        st.merge
    }
}

/// Tells the other workers to stop when a task's render panics, so none
/// waits for the lost task's merge (the pool then re-raises the panic).
struct AbandonOnPanic<'q, 'a>(&'q TaskQueue<'a>);

impl Drop for AbandonOnPanic<'_, '_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.lock().abandoned = true;
            self.0.merged.notify_all();
        }
    }
}

/// A bar over the pixel samples `samples` of every pixel of `film`.
fn progress_bar(visible: bool, film: &Film, samples: &Range<u32>) -> ProgressBar {
    if !visible {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(film.sums.len() as u64 * samples.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {percent}% (eta {eta})")
            .expect("progress template"),
    );
    bar
}

/// `strategies`: with per-strategy images, their `max_length`.
fn render_task(
    scene: &Scene,
    integrator: &dyn Integrator,
    seed: u64,
    ws: &mut Workspace,
    strategies: Option<u32>,
    width: u32,
    task: &Task,
) -> TaskOutput {
    let Task { origin, size, ref samples } = *task;
    let mut out = TaskOutput {
        origin,
        size,
        spp: samples.len() as u64,
        sums: vec![[0; 3]; (size.x * size.y) as usize],
        splats: Vec::new(),
        dropped: DroppedSamples::default(),
        rays: 0,
        strategies: strategies.map(TaskStrategies::new),
    };
    let image = UVec2::new(width, scene.camera.height);
    crate::scene::take_ray_count();
    for y in 0..size.y {
        for x in 0..size.x {
            let pixel = origin + UVec2::new(x, y);
            let local = (y * size.x + x) as usize;
            for first in samples.clone().step_by(LANES) {
                // Up to LANES samples at a time, each with its own stream
                // (the vectors are the worker's, taken out while in use).
                let last = first.saturating_add(LANES as u32).min(samples.end);
                let stream = (pixel.y * width + pixel.x) as u64;
                let (mut samplers, mut lambdas) = (std::mem::take(&mut ws.samplers), std::mem::take(&mut ws.lambdas));
                samplers.clear();
                samplers.extend((first..last).map(|s| Sampler::new(seed, stream, s as u64)));
                lambdas.clear();
                lambdas.extend(samplers.iter_mut().map(|s| SampledWavelengths::sample_visible(s.get1d())));
                // (A lone sample goes alone: a packet of one costs more.)
                let lanes = match ws.strategies {
                    None if samplers.len() > 1 => integrator.sample_lanes(scene, pixel, &mut samplers, &mut lambdas),
                    _ => None,
                };
                match lanes {
                    Some(l) => {
                        for (l, lambda) in l.iter().zip(&lambdas) {
                            out.add_sample(local, *l, &[], &SampledCmf::linear_srgb(lambda), image);
                        }
                    }
                    None => {
                        for (sampler, lambda) in samplers.iter_mut().zip(&mut lambdas) {
                            out.add_one(scene, integrator, ws, pixel, local, sampler, lambda, image);
                        }
                    }
                }
                (ws.samplers, ws.lambdas) = (samplers, lambdas);
            }
        }
    }
    out.rays = crate::scene::take_ray_count();
    out
}

/// The index of the pixel of an `image`-sized film that holds `raster`
/// (clamped: a point on the far edge belongs to the last pixel).
pub(crate) fn splat_pixel(raster: Vec2, image: UVec2) -> u32 {
    let p = raster.as_uvec2().min(image - 1);
    p.y * image.x + p.x
}

impl TaskOutput {
    /// One sample taken alone (`Integrator::sample`), with its splats and
    /// strategy records.
    #[allow(clippy::too_many_arguments)]
    fn add_one(
        &mut self,
        scene: &Scene,
        integrator: &dyn Integrator,
        ws: &mut Workspace,
        pixel: UVec2,
        local: usize,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
        image: UVec2,
    ) {
        ws.splats.clear();
        if let Some(records) = ws.strategies.as_mut() {
            records.clear();
        }
        let l = integrator.sample(scene, pixel, sampler, lambda, ws);
        let cmf = SampledCmf::linear_srgb(lambda);
        self.add_sample(local, l, &ws.splats, &cmf, image);
        let n = self.sums.len();
        if let (Some(task), Some(records)) = (self.strategies.as_mut(), ws.strategies.as_ref()) {
            task.add(records, local, n, &cmf, image);
        }
    }

    /// One camera sample of the task's pixel `local` (value `l`) and the
    /// splats it made, converted to colour with the matching functions at
    /// the sample's final wavelengths; what the film cannot take is counted,
    /// not added. A zero estimate (light tracing's, always) adds nothing.
    fn add_sample(&mut self, local: usize, l: SampledSpectrum, splats: &[Splat], cmf: &SampledCmf, image: UVec2) {
        if l.0 != Vec4::ZERO {
            if let Some(rgb) = self.dropped.admit(l, cmf) {
                if !add_fixed(&mut self.sums[local], to_fixed(rgb)) {
                    self.dropped.infinite += 1;
                }
            }
        }
        for sp in splats {
            if let Some(rgb) = self.dropped.admit(sp.l, cmf) {
                self.splats.push((splat_pixel(sp.raster, image), rgb));
            }
        }
    }
}

/// Adds a task's sums to the film (its splats go through
/// `Merge::add_splats`). What would carry a pixel's sum out of the film's
/// range is dropped and counted as infinite: a splat, or the task's samples
/// of a pixel.
fn merge_task(film: &mut Film, out: TaskOutput) {
    for y in 0..out.size.y {
        for x in 0..out.size.x {
            let i = ((out.origin.y + y) * film.width + out.origin.x + x) as usize;
            if !add_fixed(&mut film.sums[i], out.sums[(y * out.size.x + x) as usize]) {
                film.dropped.infinite += out.spp;
            }
        }
    }
    film.dropped.merge(&out.dropped);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One thread's renders reuse its pool while the thread count stays,
    /// and another thread's get their own.
    #[test]
    fn renders_of_a_thread_share_its_pool() {
        let opts = |threads| RenderOptions { seed: 0, threads, progress: false };
        let address = |p: &Rc<ThreadPool>| Rc::as_ptr(p) as usize;
        let first = thread_pool(&opts(2));
        assert!(Rc::ptr_eq(&first, &thread_pool(&opts(2))));
        assert_eq!(first.current_num_threads(), 2);
        let other = thread_pool(&opts(3));
        assert_eq!(other.current_num_threads(), 3);
        let elsewhere = std::thread::spawn(move || address(&thread_pool(&opts(3)))).join().unwrap();
        assert_ne!(elsewhere, address(&other), "another thread's render shared this one's pool");
    }

    /// Every (pixel, sample index) of a render is in exactly one task, a
    /// task's run starts on a packet boundary and is at most `MAX_RUN`
    /// long, and an image of fewer tiles than `MIN_TASKS` is cut into runs
    /// while a larger one is cut only past `MAX_RUN` samples.
    #[test]
    fn tasks_cover_every_pixel_sample_once() {
        let all = |t: &Tasks| (0..t.len()).map(|i| t.get(i)).collect::<Vec<_>>();
        let top = u32::MAX - 100..u32::MAX;
        for (w, h, samples) in [
            (16, 16, 0..4096),
            (16, 16, 3..40),
            (40, 24, 0..64),
            (8, 8, 0..1),
            (144, 128, 0..9),
            (144, 128, 0..1000),
            (16, 16, top),
        ] {
            let n = samples.len();
            let mut count = vec![0u32; (w * h) as usize * n];
            for t in all(&Tasks::new(w, h, samples.clone())) {
                assert_eq!((t.samples.start - samples.start) % LANES as u32, 0, "{t:?}");
                assert!(t.samples.len() as u64 <= MAX_RUN, "{t:?}");
                for (y, x) in (0..t.size.y).flat_map(|y| (0..t.size.x).map(move |x| (y, x))) {
                    let pixel = ((t.origin.y + y) * w + t.origin.x + x) as usize;
                    for s in t.samples.clone() {
                        count[pixel * n + (s - samples.start) as usize] += 1;
                    }
                }
            }
            assert!(count.iter().all(|&c| c == 1), "{w}x{h}, samples {samples:?}: not a partition");
        }
        assert_eq!(Tasks::new(16, 16, 0..4096).len(), MIN_TASKS);
        assert_eq!(Tasks::new(40, 24, 0..64).len(), 6 * 8);
        assert_eq!(Tasks::new(144, 128, 0..64).len(), 9 * 8, "an image of 72 tiles at 64 spp was cut");
        assert_eq!(Tasks::new(144, 128, 0..4096).len(), 9 * 8 * 64);
        assert_eq!(Tasks::new(16, 16, 0..0).len(), 0);
        // Ranges too long to list: each tile's runs follow one another from
        // the range's start to its end (the first and last few of each).
        for (w, h, samples) in [(144, 128, 0..u32::MAX), (144, 128, 1..u32::MAX), (16, 16, 0..u32::MAX)] {
            let tasks = Tasks::new(w, h, samples.clone());
            assert_eq!(tasks.len(), tile_grid(w, h).len() * (samples.len() as u64).div_ceil(MAX_RUN) as usize);
            for tile in 0..tile_grid(w, h).len() {
                let (first, last) = (tile * tasks.runs, (tile + 1) * tasks.runs - 1);
                let ends = [first, first + 1, first + 2, last - 2, last - 1, last].map(|i| tasks.get(i).samples);
                assert_eq!((ends[0].start, ends[5].end), (samples.start, samples.end), "{w}x{h}, {samples:?}");
                assert!(ends[..3].windows(2).chain(ends[3..].windows(2)).all(|p| p[0].end == p[1].start));
                assert!(ends.iter().all(|r| !r.is_empty()), "{w}x{h}, {samples:?}: an empty task");
            }
        }
    }
}
