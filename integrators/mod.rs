//! The estimators: one file each, sharing the scene, BSDFs, lights and (for
//! the bidirectional ones) the subpath machinery of src/path.rs. Adding one is
//! adding a file and a line to `INTEGRATORS`.

mod bdpt;
mod light;
mod path;
mod simple_path;

pub use bdpt::{init_mis, mis_weight, Bdpt, Subpath};

use crate::accel::LANES;
use crate::render::Workspace;
use crate::sampling::{MisHeuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use glam::UVec2;

/// One unbiased estimator of the pixel integral (box filter, CIE-weighted
/// spectral radiance, see ARCHITECTURE.md).
pub trait Integrator: Send + Sync {
    /// One sample for `pixel`: returns the estimate of that pixel's value and
    /// may add splats (to any pixel) to `ws.splats`. `lambda` may be changed
    /// (secondary wavelengths terminated) by the sample.
    fn sample(
        &self,
        scene: &Scene,
        pixel: UVec2,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
        ws: &mut Workspace,
    ) -> SampledSpectrum;

    /// Two to `LANES` samples of one pixel at once (`samplers[i]` and
    /// `lambdas[i]` as `sample` takes them), for an estimator that traces
    /// some of their rays together; it may make no splats. `None`, the
    /// default, has the samples taken one at a time by `sample`.
    fn sample_lanes(
        &self,
        _scene: &Scene,
        _pixel: UVec2,
        _samplers: &mut [Sampler],
        _lambdas: &mut [SampledWavelengths],
    ) -> Option<[SampledSpectrum; LANES]> {
        None
    }

    /// Path classes the scene contains that this estimator cannot sample, in
    /// plain words (printed as warnings before rendering).
    fn unsamplable(&self, _scene: &Scene) -> Vec<String> {
        Vec::new()
    }
}

/// Settings every integrator understands.
#[derive(Clone, Debug)]
pub struct IntegratorOptions {
    /// Maximum number of scattering events; roulette usually ends paths first.
    pub max_depth: u32,
    /// How BDPT weights its strategies (the other estimators ignore it).
    pub mis: MisHeuristic,
}

impl Default for IntegratorOptions {
    fn default() -> Self {
        Self { max_depth: 1024, mis: MisHeuristic::Power }
    }
}

pub struct IntegratorInfo {
    pub name: &'static str,
    pub description: &'static str,
    pub create: fn(&IntegratorOptions) -> Box<dyn Integrator>,
    /// Whether it reads `IntegratorOptions::mis`. The others ignore it, so
    /// a render records the default for them: parts rendered with and
    /// without `--mis` hold the same image and must merge.
    pub reads_mis: bool,
}

pub const INTEGRATORS: &[IntegratorInfo] = &[
    IntegratorInfo {
        name: "simple_path",
        description: "path tracing with BSDF sampling only (no NEE, no MIS): the obviously correct baseline",
        create: |o| Box::new(simple_path::SimplePath::new(o)),
        reads_mis: false,
    },
    IntegratorInfo {
        name: "path",
        description: "path tracing with next-event estimation and BSDF sampling combined by the power heuristic",
        create: |o| Box::new(path::PathTracer::new(o)),
        reads_mis: false,
    },
    IntegratorInfo {
        name: "light",
        description: "light tracing (particle tracing): light paths connected to the pinhole and splatted",
        create: |o| Box::new(light::LightTracer::new(o)),
        reads_mis: false,
    },
    IntegratorInfo {
        name: "bdpt",
        description: "bidirectional path tracing: every (s, t) connection strategy, combined by MIS (--mis)",
        create: |o| Box::new(bdpt::Bdpt::new(o)),
        reads_mis: true,
    },
];

/// The integrator called `name`, or an error that lists the valid names.
pub fn create(name: &str, opts: &IntegratorOptions) -> Result<Box<dyn Integrator>, String> {
    INTEGRATORS.iter().find(|i| i.name == name).map(|i| (i.create)(opts)).ok_or_else(|| {
        let names: Vec<&str> = INTEGRATORS.iter().map(|i| i.name).collect();
        format!("unknown integrator \"{name}\" (valid: {})", names.join(", "))
    })
}

/// Whether the integrator called `name` reads `IntegratorOptions::mis`
/// (false for unknown names).
pub fn reads_mis(name: &str) -> bool {
    INTEGRATORS.iter().any(|i| i.name == name && i.reads_mis)
}

/// The MIS heuristic a render of `name` uses: `mis` if it reads one, else
/// the default, which is what its sidecar and state record.
pub fn effective_mis(name: &str, mis: MisHeuristic) -> MisHeuristic {
    if reads_mis(name) {
        mis
    } else {
        MisHeuristic::default()
    }
}
