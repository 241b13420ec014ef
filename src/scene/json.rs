//! The JSON scene loader (format: docs/scene-format.md).
//!
//! Parsing is two-staged: serde reads the file into the `*Spec` types below
//! (`deny_unknown_fields`, so a misspelt parameter is an error, as in
//! Mitsuba), then `build` turns names into spectra, materials and meshes.
//! Every error names the file, line, column and field path:
//! `scenes/x.json:14:9: materials.glass.ior: unknown spectrum "BK8" (known: ...)`.

use super::locate::{locate, path_string, Seg};
use super::tagged::tagged_enum;
use super::{check_triangle_count, RenderDefaults, SceneBuilder};
use crate::camera::Camera;
use crate::materials::{roughness_to_alpha, Bsdf, Conductor, Dielectric, Diffuse, Mirror};
use crate::shapes::Mesh;
use crate::spectrum::{self, Spectrum};
use glam::{Affine3A, Quat, Vec3, Vec3A};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// A scene file that could not be read or understood.
#[derive(Debug)]
pub struct LoadError {
    pub file: String,
    /// 1-based line and column, when known.
    pub position: Option<(usize, usize)>,
    /// Field path such as `objects[2].material`, when known.
    pub field: String,
    pub message: String,
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some((l, c)) = self.position {
            write!(f, ":{l}:{c}")?;
        }
        if !self.field.is_empty() {
            write!(f, ": {}", self.field)?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for LoadError {}

// ---------------------------------------------------------------- file format

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    comment: Option<String>,
    camera: CameraSpec,
    #[serde(default, deserialize_with = "unique_names")]
    spectra: BTreeMap<String, SpectrumSpec>,
    #[serde(default, deserialize_with = "unique_names")]
    materials: BTreeMap<String, MaterialSpec>,
    #[serde(default)]
    objects: Vec<ObjectSpec>,
    #[serde(default)]
    lights: Vec<LightSpec>,
    #[serde(default)]
    render: RenderSpec,
}

/// A map of named entries in which a repeated name is an error (a plain
/// map would silently keep the last one).
fn unique_names<'de, D, V>(d: D) -> Result<BTreeMap<String, V>, D::Error>
where
    D: serde::Deserializer<'de>,
    V: Deserialize<'de>,
{
    d.deserialize_map(Names(std::marker::PhantomData))
}

/// The visitor of `unique_names`.
struct Names<V>(std::marker::PhantomData<V>);

impl<'de, V: Deserialize<'de>> serde::de::Visitor<'de> for Names<V> {
    type Value = BTreeMap<String, V>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object of named entries")
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut out = BTreeMap::new();
        while let Some(name) = map.next_key::<String>()? {
            if out.contains_key(&name) {
                return Err(serde::de::Error::custom(format!("duplicate name \"{name}\"")));
            }
            let value = map.next_value()?;
            out.insert(name, value);
        }
        Ok(out)
    }
}

/// `N` values written as a JSON array of exactly `N`. serde's own arrays
/// stop reading after the `N`th value, so a longer one failed as "trailing
/// characters"; this one counts what was given (`expected 3 numbers
/// [x, y, z], got 4`).
#[derive(Clone, Copy)]
struct Fixed<T, const N: usize>([T; N]);

/// A point or a direction.
type Xyz = Fixed<f32, 3>;

/// What a `Fixed` array holds, as its errors name it.
trait Element {
    /// `n` of them, e.g. "3 numbers [x, y, z]".
    fn count(n: usize) -> String;
}

impl Element for f32 {
    fn count(n: usize) -> String {
        // Every triple of numbers in a scene is a point or a direction.
        match n {
            3 => "3 numbers [x, y, z]".to_string(),
            _ => format!("{n} numbers"),
        }
    }
}

impl Element for u32 {
    // (A triangle's vertex indices are the only integers in arrays.)
    fn count(n: usize) -> String {
        format!("{n} vertex indices")
    }
}

impl Element for Xyz {
    fn count(n: usize) -> String {
        format!("{n} points [x, y, z]")
    }
}

impl<'de, T: Deserialize<'de> + Element, const N: usize> Deserialize<'de> for Fixed<T, N> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_seq(FixedVisitor(std::marker::PhantomData))
    }
}

/// The visitor of `Fixed`.
struct FixedVisitor<T, const N: usize>(std::marker::PhantomData<T>);

impl<'de, T: Deserialize<'de> + Element, const N: usize> serde::de::Visitor<'de> for FixedVisitor<T, N> {
    type Value = Fixed<T, N>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(&T::count(N))
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut values = Vec::with_capacity(N);
        while values.len() < N {
            match seq.next_element()? {
                Some(v) => values.push(v),
                None => break,
            }
        }
        // Values beyond the N are only counted, for the message.
        let mut n = values.len();
        while seq.next_element::<serde::de::IgnoredAny>()?.is_some() {
            n += 1;
        }
        match values.try_into() {
            Ok(array) if n == N => Ok(Fixed(array)),
            _ => Err(serde::de::Error::custom(format!("expected {}, got {n}", T::count(N)))),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraSpec {
    position: Xyz,
    look_at: Xyz,
    #[serde(default = "default_up")]
    up: Xyz,
    /// Full vertical field of view in degrees.
    fov: f32,
    width: u32,
    height: u32,
}

fn default_up() -> Xyz {
    Fixed([0.0, 1.0, 0.0])
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RenderSpec {
    spp: Option<u32>,
    max_depth: Option<u32>,
    integrator: Option<String>,
    seed: Option<Seed>,
}

/// `render.seed`: any u64. serde's own messages named a type, not the
/// range: 2^64, which serde_json reads as a float, was "invalid type:
/// floating point `1.8446744073709552e+19`, expected u64".
struct Seed(u64);

impl<'de> Deserialize<'de> for Seed {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_u64(SeedVisitor)
    }
}

/// The visitor of `Seed`.
struct SeedVisitor;

impl SeedVisitor {
    /// The error for `got`, with the range `expecting` gives.
    fn refuse<E: serde::de::Error>(&self, got: impl fmt::Display) -> E {
        E::custom(format!("seed must be {}, got {got}", self as &dyn serde::de::Expected))
    }
}

impl serde::de::Visitor<'_> for SeedVisitor {
    type Value = Seed;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "an integer in 0..={}", u64::MAX)
    }
    fn visit_u64<E>(self, x: u64) -> Result<Seed, E> {
        Ok(Seed(x))
    }
    fn visit_i64<E: serde::de::Error>(self, x: i64) -> Result<Seed, E> {
        u64::try_from(x).map(Seed).map_err(|_| self.refuse(x))
    }
    /// A fraction, an exponent, or an integer beyond i64 and u64. (Debug
    /// keeps a float a float: `1000.0` for `1e3`, not `1000`.)
    fn visit_f64<E: serde::de::Error>(self, x: f64) -> Result<Seed, E> {
        Err(self.refuse(format!("{x:?}")))
    }
}

enum MaterialSpec {
    Diffuse(DiffuseSpec),
    Conductor(ConductorSpec),
    Dielectric(DielectricSpec),
    Mirror(MirrorSpec),
}

tagged_enum!(MaterialSpec, "a material", {
    "diffuse" => Diffuse(DiffuseSpec),
    "conductor" => Conductor(ConductorSpec),
    "dielectric" => Dielectric(DielectricSpec),
    "mirror" => Mirror(MirrorSpec),
});

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ConductorSpec {
    #[serde(default)]
    metal: Option<String>,
    #[serde(default)]
    eta: Option<SpectrumSpec>,
    #[serde(default)]
    k: Option<SpectrumSpec>,
    roughness: Option<f32>,
    alpha: Option<f32>,
    alpha_x: Option<f32>,
    alpha_y: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DielectricSpec {
    #[serde(default = "default_ior")]
    ior: SpectrumSpec,
    roughness: Option<f32>,
    alpha: Option<f32>,
    alpha_x: Option<f32>,
    alpha_y: Option<f32>,
}

fn default_ior() -> SpectrumSpec {
    SpectrumSpec::Constant(1.5)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MirrorSpec {
    #[serde(default = "one")]
    reflectance: SpectrumSpec,
}

fn one() -> SpectrumSpec {
    SpectrumSpec::Constant(1.0)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DiffuseSpec {
    #[serde(default = "half")]
    reflectance: SpectrumSpec,
}

fn half() -> SpectrumSpec {
    SpectrumSpec::Constant(0.5)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectSpec {
    #[serde(default)]
    name: Option<String>,
    /// Accepted (the format allows a note on any object) and never read.
    #[serde(default, rename = "comment")]
    _comment: Option<String>,
    shape: ShapeSpec,
    /// Required, except for a `gltf` shape (whose materials map themselves).
    #[serde(default)]
    material: Option<String>,
    #[serde(default)]
    emission: Option<SpectrumSpec>,
    #[serde(default)]
    two_sided: bool,
    #[serde(default)]
    transform: Option<TransformSpec>,
}

enum ShapeSpec {
    Quad(QuadSpec),
    Cuboid(CuboidSpec),
    Sphere(SphereSpec),
    Mesh(InlineMeshSpec),
    Obj(ObjSpec),
    Gltf(GltfSpec),
}

impl ShapeSpec {
    /// Triangles a sphere will have (the shape a line of text can make
    /// millions of), 0 for the others, which count as they are made.
    fn declared_triangles(&self) -> usize {
        match self {
            ShapeSpec::Sphere(s) if s.subdivisions <= MAX_SUBDIVISIONS => Mesh::sphere_triangles(s.subdivisions),
            _ => 0,
        }
    }
}

tagged_enum!(ShapeSpec, "a shape", {
    "quad" => Quad(QuadSpec),
    "cuboid" => Cuboid(CuboidSpec),
    "sphere" => Sphere(SphereSpec),
    "mesh" => Mesh(InlineMeshSpec),
    "obj" => Obj(ObjSpec),
    "gltf" => Gltf(GltfSpec),
});

/// A glTF file as one object (docs/scene-format.md, "glTF scenes").
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GltfSpec {
    /// Relative to the scene file.
    file: String,
    /// glTF material name (or `#index`) -> a key of the scene's `materials`.
    #[serde(default, deserialize_with = "unique_names")]
    materials: BTreeMap<String, String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct QuadSpec {
    corners: Fixed<Xyz, 4>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CuboidSpec {
    min: Xyz,
    max: Xyz,
    /// Wind inward (normals point inside), for a room seen from inside.
    #[serde(default)]
    inward: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SphereSpec {
    center: Xyz,
    radius: f32,
    #[serde(default = "default_subdivisions")]
    subdivisions: u32,
    #[serde(default)]
    smooth: bool,
    /// Wind inward (normals point to the centre), for a sphere seen from inside.
    #[serde(default)]
    inward: bool,
}

/// A sphere of 9 subdivisions has 5,242,880 triangles.
const MAX_SUBDIVISIONS: u32 = 9;

fn default_subdivisions() -> u32 {
    4
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InlineMeshSpec {
    positions: Vec<Xyz>,
    indices: Vec<Fixed<u32, 3>>,
    #[serde(default)]
    normals: Vec<Xyz>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjSpec {
    /// Relative to the scene file.
    file: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TransformSpec {
    #[serde(default)]
    scale: Option<ScaleSpec>,
    #[serde(default)]
    rotate: Option<RotateSpec>,
    #[serde(default)]
    translate: Option<Xyz>,
}

#[derive(Deserialize)]
#[serde(untagged, expecting = "expected a number or [x, y, z]")]
enum ScaleSpec {
    Uniform(f32),
    PerAxis([f32; 3]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RotateSpec {
    axis: Xyz,
    degrees: f32,
}

enum LightSpec {
    Point(PointSpec),
    Environment(EnvironmentSpec),
}

tagged_enum!(LightSpec, "a light", {
    "point" => Point(PointSpec),
    "environment" => Environment(EnvironmentSpec),
});

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PointSpec {
    #[serde(default)]
    name: Option<String>,
    position: Xyz,
    intensity: SpectrumSpec,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentSpec {
    #[serde(default)]
    name: Option<String>,
    radiance: SpectrumSpec,
}

/// How a scene writes a spectrum: a number (constant), a name (an entry of
/// `spectra`, or a built-in illuminant / glass), or an object with one of
/// `rgb`, `blackbody`, `wavelengths`+`values`, `sellmeier`, `cauchy`, and an
/// optional `scale`.
#[derive(Clone, Debug)]
enum SpectrumSpec {
    Constant(f32),
    Name(String),
    Rgb([f32; 3], f32),
    Blackbody(f32, f32),
    Tabulated(Vec<f32>, Vec<f32>, f32),
    Sellmeier([f32; 3], [f32; 3]),
    Cauchy(f32, f32),
}

const SPECTRUM_FORMS: &str =
    "expected a number, a spectrum name, or an object with one of \"rgb\", \"blackbody\", \"wavelengths\"+\"values\", \"sellmeier\", \"cauchy\"";

impl<'de> Deserialize<'de> for SpectrumSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let v = d.deserialize_any(SpectrumValue)?;
        spectrum_from_value(&v).map_err(D::Error::custom)
    }
}

/// A spectrum's JSON value: a number, a name, or an object whose keys
/// (`unique_names`: a repeated "rgb" is an error, not the last one kept)
/// `spectrum_from_value` reads. Anything else is refused with the forms.
struct SpectrumValue;

impl<'de> serde::de::Visitor<'de> for SpectrumValue {
    type Value = serde_json::Value;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        // (serde's message already says "expected".)
        f.write_str(SPECTRUM_FORMS.trim_start_matches("expected "))
    }
    fn visit_u64<E>(self, x: u64) -> Result<Self::Value, E> {
        Ok(x.into())
    }
    fn visit_i64<E>(self, x: i64) -> Result<Self::Value, E> {
        Ok(x.into())
    }
    fn visit_f64<E>(self, x: f64) -> Result<Self::Value, E> {
        Ok(x.into())
    }
    fn visit_str<E>(self, s: &str) -> Result<Self::Value, E> {
        Ok(s.into())
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        let fields: BTreeMap<String, serde_json::Value> = Names(std::marker::PhantomData).visit_map(map)?;
        Ok(serde_json::Value::Object(fields.into_iter().collect()))
    }
}

fn spectrum_from_value(v: &serde_json::Value) -> Result<SpectrumSpec, String> {
    use serde_json::Value;
    let num =
        |v: &Value, what: &str| v.as_f64().map(|x| x as f32).ok_or_else(|| format!("\"{what}\" must be a number"));
    let arr = |v: &Value, what: &str| -> Result<Vec<f32>, String> {
        v.as_array()
            .and_then(|a| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect::<Option<Vec<f32>>>())
            .ok_or_else(|| format!("\"{what}\" must be an array of numbers"))
    };
    // `parts` names the three, as `Fixed` does a point's.
    let arr3 = |v: &Value, what: &str, parts: &str| -> Result<[f32; 3], String> {
        let a = arr(v, what)?;
        let n = a.len();
        a.try_into().map_err(|_| format!("\"{what}\": expected 3 numbers {parts}, got {n}"))
    };
    match v {
        Value::Number(n) => Ok(SpectrumSpec::Constant(n.as_f64().unwrap_or(f64::NAN) as f32)),
        Value::String(s) => Ok(SpectrumSpec::Name(s.clone())),
        Value::Object(o) => {
            let scale = o.get("scale").map(|s| num(s, "scale")).transpose()?.unwrap_or(1.0);
            let allowed: &[&str] = if o.contains_key("rgb") {
                &["rgb", "scale"]
            } else if o.contains_key("blackbody") {
                &["blackbody", "scale"]
            } else if o.contains_key("wavelengths") {
                &["wavelengths", "values", "scale"]
            } else if o.contains_key("sellmeier") {
                &["sellmeier"]
            } else if o.contains_key("cauchy") {
                &["cauchy"]
            } else {
                return Err(SPECTRUM_FORMS.to_string());
            };
            if let Some(k) = o.keys().find(|k| !allowed.contains(&k.as_str())) {
                return Err(format!("unknown field \"{k}\" (expected {})", allowed.join(", ")));
            }
            if let Some(v) = o.get("rgb") {
                return Ok(SpectrumSpec::Rgb(arr3(v, "rgb", "[r, g, b]")?, scale));
            }
            if let Some(v) = o.get("blackbody") {
                return Ok(SpectrumSpec::Blackbody(num(v, "blackbody")?, scale));
            }
            if let Some(v) = o.get("wavelengths") {
                let w = arr(v, "wavelengths")?;
                let vals = arr(o.get("values").ok_or("\"wavelengths\" needs \"values\"")?, "values")?;
                return Ok(SpectrumSpec::Tabulated(w, vals, scale));
            }
            let coeffs = |v: &Value, a: &str, b: &str| -> Result<(Value, Value), String> {
                let o = v.as_object().ok_or_else(|| format!("expected an object with \"{a}\" and \"{b}\""))?;
                if let Some(k) = o.keys().find(|k| *k != a && *k != b) {
                    return Err(format!("unknown field \"{k}\" (expected {a}, {b})"));
                }
                let get = |k: &str| o.get(k).cloned().ok_or_else(|| format!("missing \"{k}\""));
                Ok((get(a)?, get(b)?))
            };
            if let Some(v) = o.get("sellmeier") {
                let (b, c) = coeffs(v, "b", "c")?;
                return Ok(SpectrumSpec::Sellmeier(arr3(&b, "b", "[b1, b2, b3]")?, arr3(&c, "c", "[c1, c2, c3]")?));
            }
            let (a, b) = coeffs(&o["cauchy"], "a", "b")?;
            Ok(SpectrumSpec::Cauchy(num(&a, "a")?, num(&b, "b")?))
        }
        _ => Err(SPECTRUM_FORMS.to_string()),
    }
}

// ------------------------------------------------------------------ resolving

/// The largest index of refraction or extinction coefficient a scene may
/// give: no material comes within orders of magnitude of it, and from ~4e9
/// on the conductor Fresnel terms (eta^2 + k^2)^2 overflow f32 (a rough
/// conductor with k = 1e10 turned every sample that met it into NaN).
const MAX_INDEX: f32 = 1e6;

/// What a spectrum is used as: decides how RGB is upsampled and which
/// built-in names apply.
#[derive(Clone, Copy, PartialEq)]
enum Use {
    Reflectance,
    Emission,
    Ior,
    /// No built-in names and no RGB meaning beyond a reflectance-like shape.
    Other,
}

struct Ctx<'a> {
    file: &'a str,
    text: &'a str,
    dir: &'a Path,
    /// The scene's `spectra`, each entry that names another replaced by
    /// what its chain of names ends at (`follow_names`).
    spectra: BTreeMap<&'a str, &'a SpectrumSpec>,
}

/// The scene's `spectra` with every chain of names followed to its end: an
/// entry that is not a name, or a name the scene does not define (a
/// built-in, or unknown). Err(a cycle, its first name repeated at the end)
/// if the names form one. Each entry is walked once, however long the chain.
fn follow_names(spectra: &BTreeMap<String, SpectrumSpec>) -> Result<BTreeMap<&str, &SpectrumSpec>, Vec<&str>> {
    // None: on the chain being followed (every earlier chain has its end).
    let mut ends: BTreeMap<&str, Option<&SpectrumSpec>> = BTreeMap::new();
    for (start, first) in spectra {
        if ends.contains_key(start.as_str()) {
            continue;
        }
        let (mut chain, mut spec) = (vec![start.as_str()], first);
        ends.insert(start, None);
        while let SpectrumSpec::Name(next) = spec {
            match (ends.get(next.as_str()).copied(), spectra.get(next)) {
                (Some(Some(end)), _) => spec = end,
                (Some(None), _) => {
                    let from = chain.iter().position(|n| n == next).unwrap_or_default();
                    return Err([&chain[from..], &[next.as_str()]].concat());
                }
                (None, Some(s)) => {
                    chain.push(next);
                    ends.insert(next, None);
                    spec = s;
                }
                (None, None) => break,
            }
        }
        chain.into_iter().for_each(|n| _ = ends.insert(n, Some(spec)));
    }
    Ok(ends.into_iter().filter_map(|(n, end)| Some((n, end?))).collect())
}

impl<'a> Ctx<'a> {
    /// Refuses a cycle of names in `spectra` where its first name is
    /// defined (where it is used, one name of the cycle looked like the fault).
    fn new(
        file: &'a str,
        text: &'a str,
        dir: &'a Path,
        spectra: &'a BTreeMap<String, SpectrumSpec>,
    ) -> Result<Self, LoadError> {
        let mut ctx = Ctx { file, text, dir, spectra: BTreeMap::new() };
        ctx.spectra = follow_names(spectra).map_err(|cycle| {
            let message = match cycle.as_slice() {
                [one, _] => format!("spectrum \"{one}\" names itself"),
                _ => format!("spectra \"{}\" form a cycle", cycle.join("\" -> \"")),
            };
            ctx.err(&[Seg::Key("spectra".into()), Seg::Key(cycle[0].to_string())], message)
        })?;
        Ok(ctx)
    }

    fn err(&self, path: &[Seg], message: impl Into<String>) -> LoadError {
        LoadError {
            file: self.file.to_string(),
            position: Some(locate(self.text, path)),
            field: path_string(path),
            message: message.into(),
        }
    }

    fn finite(&self, path: &[Seg], values: &[f32]) -> Result<(), LoadError> {
        if values.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(self.err(path, "numbers must be finite and within the f32 range (magnitude < 3.4e38)"))
        }
    }

    fn vec3(&self, path: &[Seg], Fixed(v): Xyz) -> Result<Vec3A, LoadError> {
        self.finite(path, &v)?;
        Ok(Vec3A::from_array(v))
    }

    fn spectrum(&self, path: &[Seg], spec: &SpectrumSpec, usage: Use) -> Result<Spectrum, LoadError> {
        let s = match spec {
            SpectrumSpec::Constant(c) => Spectrum::Constant(self.non_negative(path, *c, "a spectrum value")?),
            SpectrumSpec::Name(name) => return self.named_spectrum(path, name, usage),
            SpectrumSpec::Rgb(rgb, scale) => {
                self.finite(path, rgb)?;
                let scale = self.scale(path, *scale)?;
                self.rgb_spectrum(path, rgb, usage)?.scale(scale)
            }
            SpectrumSpec::Blackbody(t, scale) => {
                if !(t.is_finite() && *t > 0.0) {
                    return Err(self.err(path, "blackbody temperature must be > 0 kelvin"));
                }
                let b = spectrum::blackbody(*t);
                if b.max_value() == 0.0 {
                    let why = format!("a blackbody at {t} K emits no visible light to normalise (it underflows)");
                    return Err(self.err(path, why));
                }
                b.scale(self.scale(path, *scale)?)
            }
            SpectrumSpec::Tabulated(w, v, scale) => {
                self.tabulated_spectrum(path, w, v)?.scale(self.scale(path, *scale)?)
            }
            SpectrumSpec::Sellmeier(b, c) => {
                self.finite(path, b)?;
                self.finite(path, c)?;
                spectrum::sellmeier(*b, *c)
            }
            SpectrumSpec::Cauchy(a, b) => {
                self.finite(path, &[*a, *b])?;
                spectrum::cauchy(*a, *b)
            }
        };
        self.check_spectrum(path, s, usage)
    }

    fn non_negative(&self, path: &[Seg], x: f32, what: &str) -> Result<f32, LoadError> {
        if x.is_finite() && x >= 0.0 {
            Ok(x)
        } else {
            Err(self.err(path, format!("{what} must be a finite number >= 0, got {x}")))
        }
    }

    fn scale(&self, path: &[Seg], scale: f32) -> Result<f32, LoadError> {
        self.non_negative(path, scale, "scale")
    }

    /// A name: one of the scene's `spectra` (followed to the end of its
    /// chain of names, so this recurses once at most), else a built-in of
    /// the use (glasses for an IOR, illuminants for emission; reflectances
    /// have none).
    fn named_spectrum(&self, path: &[Seg], name: &str, usage: Use) -> Result<Spectrum, LoadError> {
        if let Some(s) = self.spectra.get(name) {
            return self.spectrum(path, s, usage);
        }
        let (builtin, builtins) = match usage {
            Use::Ior => (spectrum::glass_ior(name), spectrum::GLASS_NAMES),
            Use::Emission => (spectrum::illuminant(name), spectrum::ILLUMINANT_NAMES),
            Use::Reflectance | Use::Other => (None, &[][..]),
        };
        let s = builtin.ok_or_else(|| {
            let mut known: Vec<String> = self.spectra.keys().map(|n| n.to_string()).collect();
            known.extend(builtins.iter().map(|s| s.to_string()));
            if known.is_empty() {
                // Not "(known: )": say where names come from.
                let why = "the scene defines no \"spectra\"; built-in names exist only for emission and ior";
                return self.err(path, format!("unknown spectrum \"{name}\" ({why})"));
            }
            self.err(path, format!("unknown spectrum \"{name}\" (known: {})", known.join(", ")))
        })?;
        self.check_spectrum(path, s, usage)
    }

    /// Linear sRGB (finite): an illuminant shape for emission, else a
    /// reflectance-like shape in [0, 1] (Jakob & Hanika 2019), which is
    /// what a `k` or an `ior` given as rgb is too, `scale` its magnitude.
    fn rgb_spectrum(&self, path: &[Seg], rgb: &[f32; 3], usage: Use) -> Result<Spectrum, LoadError> {
        if rgb.iter().any(|&c| c < 0.0) {
            return Err(self.err(path, "rgb components must be >= 0"));
        }
        if usage == Use::Emission {
            return Ok(spectrum::rgb_illuminant(*rgb));
        }
        if rgb.iter().any(|&c| c > 1.0) {
            let what = match usage {
                Use::Reflectance => "a reflectance rgb must lie in [0, 1]",
                _ => "an rgb other than an emission is a shape in [0, 1]; \"scale\" sets its magnitude",
            };
            return Err(self.err(path, what));
        }
        Ok(spectrum::rgb_albedo(*rgb))
    }

    /// `wavelengths` and `values`: piecewise linear.
    fn tabulated_spectrum(&self, path: &[Seg], w: &[f32], v: &[f32]) -> Result<Spectrum, LoadError> {
        if w.len() != v.len() || w.is_empty() {
            return Err(self.err(path, "\"wavelengths\" and \"values\" must be non-empty and of equal length"));
        }
        self.finite(path, w)?;
        self.finite(path, v)?;
        if w.windows(2).any(|p| p[1] <= p[0]) {
            return Err(self.err(path, "\"wavelengths\" must increase strictly"));
        }
        if w[0] <= 0.0 {
            return Err(self.err(path, "\"wavelengths\" are in nanometres, all above 0"));
        }
        if v.iter().any(|&x| x < 0.0) {
            return Err(self.err(path, "spectrum values must be >= 0"));
        }
        let pts: Vec<(f32, f32)> = w.iter().copied().zip(v.iter().copied()).collect();
        Ok(Spectrum::piecewise_linear(&pts))
    }

    /// What every spectrum must be: finite and non-negative everywhere, and
    /// within the range of its use (a reflectance at most 1, an IOR above 0).
    fn check_spectrum(&self, path: &[Seg], s: Spectrum, usage: Use) -> Result<Spectrum, LoadError> {
        if !s.is_finite() {
            let why = "the spectrum is not finite at every wavelength (overflow, or a pole of the formula)";
            return Err(self.err(path, why));
        }
        // Formulas (Cauchy with b < 0) can go negative where tables cannot.
        if s.min_value() < 0.0 {
            return Err(self.err(path, format!("spectrum values must be >= 0 (min {:.3})", s.min_value())));
        }
        if usage == Use::Reflectance && s.max_value() > 1.0 {
            return Err(self.err(path, format!("a reflectance must not exceed 1 (max {})", s.max_value())));
        }
        if usage == Use::Ior && s.min_value() <= 0.0 {
            return Err(self.err(path, "an index of refraction must be > 0"));
        }
        Ok(s)
    }

    /// An index of refraction or a conductor's k, at most `MAX_INDEX`; an
    /// index of refraction at least its inverse (a rough dielectric of ior
    /// 1e-20 turned samples into NaN, as 1 / eta^2 overflowed).
    fn index(&self, path: &[Seg], spec: &SpectrumSpec, usage: Use) -> Result<Spectrum, LoadError> {
        let s = self.spectrum(path, spec, usage)?;
        if s.max_value() > MAX_INDEX {
            return Err(self.err(path, format!("must be at most {MAX_INDEX:e} (max {:e})", s.max_value())));
        }
        let min_ior = 1.0 / MAX_INDEX;
        if usage == Use::Ior && s.min_value() < min_ior {
            return Err(self.err(path, format!("must be at least {min_ior:e} (min {:e})", s.min_value())));
        }
        Ok(s)
    }

    /// An emitted radiance (an object's `emission`, an environment's
    /// `radiance`), at most `MAX_RADIANCE`.
    fn radiance(&self, path: &[Seg], spec: &SpectrumSpec) -> Result<Spectrum, LoadError> {
        let s = self.spectrum(path, spec, Use::Emission)?;
        super::check_radiance(&s).map_err(|why| self.err(path, why))?;
        Ok(s)
    }

    fn material(&self, path: &[Seg], spec: &MaterialSpec) -> Result<Bsdf, LoadError> {
        let at = |k: &str| with(path, k);
        Ok(match spec {
            MaterialSpec::Diffuse(d) => {
                Bsdf::Diffuse(Diffuse::new(self.spectrum(&at("reflectance"), &d.reflectance, Use::Reflectance)?))
            }
            MaterialSpec::Mirror(m) => {
                Bsdf::Mirror(Mirror::new(self.spectrum(&at("reflectance"), &m.reflectance, Use::Reflectance)?))
            }
            MaterialSpec::Conductor(c) => {
                let (eta, k) = match (&c.metal, &c.eta, &c.k) {
                    (Some(name), None, None) => spectrum::metal_eta_k(name).ok_or_else(|| {
                        self.err(
                            &at("metal"),
                            format!("unknown metal \"{name}\" (known: {})", spectrum::METAL_NAMES.join(", ")),
                        )
                    })?,
                    (None, Some(eta), Some(k)) => {
                        (self.index(&at("eta"), eta, Use::Ior)?, self.index(&at("k"), k, Use::Other)?)
                    }
                    (None, None, None) => spectrum::metal_eta_k("Cu").expect("Cu is a known metal"),
                    _ => return Err(self.err(path, "give either \"metal\" or both \"eta\" and \"k\"")),
                };
                let (ax, ay) = self.alphas(path, c.roughness, c.alpha, c.alpha_x, c.alpha_y)?;
                Bsdf::Conductor(Conductor::new(eta, k, ax, ay))
            }
            MaterialSpec::Dielectric(d) => {
                let eta = self.index(&at("ior"), &d.ior, Use::Ior)?;
                let (ax, ay) = self.alphas(path, d.roughness, d.alpha, d.alpha_x, d.alpha_y)?;
                let dielectric = Dielectric::new(eta, ax, ay);
                if dielectric.index_unresolved() {
                    return Err(self.err(
                        &at("ior"),
                        format!(
                            "a rough dielectric's ior must be 1 or differ from 1 by {} (here {} to {}): nearer, \
                             f32 cannot resolve its refraction (use ior 1 for an index-matched interface, a smooth \
                             one, or a rougher one)",
                            dielectric.min_index_contrast_text(),
                            dielectric.eta.min_value(),
                            dielectric.eta.max_value()
                        ),
                    ));
                }
                Bsdf::Dielectric(dielectric)
            }
        })
    }

    /// GGX alphas from exactly one of `roughness` (perceptual, alpha =
    /// roughness^2), `alpha`, or `alpha_x` with `alpha_y`; smooth if none.
    fn alphas(
        &self,
        path: &[Seg],
        roughness: Option<f32>,
        alpha: Option<f32>,
        alpha_x: Option<f32>,
        alpha_y: Option<f32>,
    ) -> Result<(f32, f32), LoadError> {
        let (field, (ax, ay)) = match (roughness, alpha, alpha_x, alpha_y) {
            (None, None, None, None) => return Ok((0.0, 0.0)),
            (Some(r), None, None, None) => ("roughness", (roughness_to_alpha(r), roughness_to_alpha(r))),
            (None, Some(a), None, None) => ("alpha", (a, a)),
            (None, None, Some(x), Some(y)) => ("alpha_x", (x, y)),
            _ => {
                return Err(self.err(path, "give one of \"roughness\", \"alpha\", or both \"alpha_x\" and \"alpha_y\""))
            }
        };
        let at = with(path, field);
        for v in [roughness, alpha, alpha_x, alpha_y].into_iter().flatten() {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(self.err(&at, format!("must lie in [0, 1], got {v}")));
            }
        }
        Ok((ax, ay))
    }

    fn shape(&self, path: &[Seg], spec: &ShapeSpec) -> Result<Mesh, LoadError> {
        let at = |k: &str| with(path, k);
        let mesh = match spec {
            ShapeSpec::Quad(q) => {
                let mut c = [Vec3A::ZERO; 4];
                for (i, v) in q.corners.0.iter().enumerate() {
                    c[i] = self.vec3(&at("corners"), *v)?;
                }
                Mesh::quad(c)
            }
            ShapeSpec::Cuboid(b) => {
                let (lo, hi) = (self.vec3(&at("min"), b.min)?, self.vec3(&at("max"), b.max)?);
                if lo.cmpgt(hi).any() {
                    return Err(self.err(&at("max"), "every component of max must be >= min"));
                }
                let mut m = Mesh::cuboid(lo, hi);
                if b.inward {
                    m.flip();
                }
                m
            }
            ShapeSpec::Sphere(s) => {
                let c = self.vec3(&at("center"), s.center)?;
                if !(s.radius.is_finite() && s.radius > 0.0) {
                    return Err(self.err(&at("radius"), "radius must be a finite number > 0"));
                }
                if s.subdivisions > MAX_SUBDIVISIONS {
                    return Err(self.err(&at("subdivisions"), "at most 9 subdivisions (5 million triangles)"));
                }
                let mut m = Mesh::sphere(c, s.radius, s.subdivisions, s.smooth);
                if s.inward {
                    m.flip();
                }
                m
            }
            ShapeSpec::Mesh(m) => self.inline_mesh(path, m)?,
            ShapeSpec::Obj(o) => self.obj(&at("file"), &o.file)?,
            ShapeSpec::Gltf(_) => return Err(self.err(path, "a gltf shape cannot be used here")),
        };
        Ok(mesh)
    }

    fn inline_mesh(&self, path: &[Seg], m: &InlineMeshSpec) -> Result<Mesh, LoadError> {
        let positions =
            m.positions.iter().map(|p| self.vec3(&with(path, "positions"), *p)).collect::<Result<Vec<_>, _>>()?;
        let normals = m.normals.iter().map(|n| self.vec3(&with(path, "normals"), *n)).collect::<Result<Vec<_>, _>>()?;
        if !normals.is_empty() && normals.len() != positions.len() {
            return Err(self.err(&with(path, "normals"), "needs one normal per position"));
        }
        let indices: Vec<[u32; 3]> = m.indices.iter().map(|t| t.0).collect();
        // As an OBJ without faces is refused: the object (a lamp, say)
        // would vanish without a word (a review, session 54).
        if indices.is_empty() {
            return Err(self.err(&with(path, "indices"), "no triangles"));
        }
        if let Some(i) = indices.iter().flatten().find(|&&i| i as usize >= positions.len()) {
            return Err(
                self.err(&with(path, "indices"), format!("index {i} is out of range ({} positions)", positions.len()))
            );
        }
        Ok(Mesh { positions, normals, indices })
    }

    fn obj(&self, path: &[Seg], file: &str) -> Result<Mesh, LoadError> {
        if file.is_empty() {
            return Err(self.err(path, "the file name is empty"));
        }
        let full: PathBuf = self.dir.join(file);
        // Only regular files: a directory fails late, /dev/zero or a FIFO would hang the loader.
        if !full.is_file() {
            let why = if full.exists() { "not a regular file" } else { "no such file" };
            return Err(self.err(path, format!("cannot read mesh {}: {why}", full.display())));
        }
        // Faces of one or two vertices (and `p` and `l` elements) have no
        // area: without the two `ignore_` options tobj padded them into
        // zero-area triangles, and a file of nothing else passed as a mesh
        // (a review, session 53).
        let opts = tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
        let (models, _) = tobj::load_obj(&full, &opts)
            .map_err(|e| self.err(path, format!("cannot read mesh {}: {e}", full.display())))?;
        let mut mesh = Mesh { positions: Vec::new(), normals: Vec::new(), indices: Vec::new() };
        // tobj gives fewer normals than positions when only some faces have
        // them; which vertices lack one it does not say.
        if let Some(m) =
            models.iter().find(|m| !m.mesh.normals.is_empty() && m.mesh.normals.len() != m.mesh.positions.len())
        {
            let msg = format!(
                "{}: object \"{}\" has normals on only some faces ({} normals for {} vertices): give every face normals, \
                 or none",
                full.display(),
                m.name,
                m.mesh.normals.len() / 3,
                m.mesh.positions.len() / 3
            );
            return Err(self.err(path, msg));
        }
        let with_normals = models.iter().all(|m| !m.mesh.normals.is_empty());
        for m in &models {
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(m.mesh.positions.chunks_exact(3).map(|p| Vec3A::new(p[0], p[1], p[2])));
            if with_normals {
                mesh.normals.extend(m.mesh.normals.chunks_exact(3).map(|n| Vec3A::new(n[0], n[1], n[2])));
            }
            mesh.indices.extend(m.mesh.indices.chunks_exact(3).map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        }
        if mesh.positions.iter().any(|p| !p.is_finite()) {
            return Err(self.err(path, format!("{}: non-finite vertex position", full.display())));
        }
        if mesh.normals.iter().any(|n| !n.is_finite()) {
            return Err(self.err(path, format!("{}: non-finite vertex normal", full.display())));
        }
        if mesh.indices.is_empty() {
            let why = format!("{}: no triangles (no `f` line of three or more vertices)", full.display());
            return Err(self.err(path, why));
        }
        Ok(mesh)
    }

    fn transform(&self, path: &[Seg], t: &TransformSpec) -> Result<Affine3A, LoadError> {
        let scale = match &t.scale {
            None => Vec3::ONE,
            Some(ScaleSpec::Uniform(s)) => Vec3::splat(*s),
            Some(ScaleSpec::PerAxis(s)) => Vec3::from_array(*s),
        };
        self.finite(&with(path, "scale"), &scale.to_array())?;
        if scale.cmpeq(Vec3::ZERO).any() {
            return Err(self.err(&with(path, "scale"), "scale must not be 0"));
        }
        let rotation = match &t.rotate {
            None => Quat::IDENTITY,
            Some(r) => {
                // Normalised in f64: in f32 a huge axis overflows to a zero, non-unit quaternion.
                let axis = Vec3::from(self.vec3(&with(path, "rotate"), r.axis)?).as_dvec3().normalize_or_zero();
                self.finite(&with(path, "rotate"), &[r.degrees])?;
                if axis == glam::DVec3::ZERO {
                    return Err(self.err(&with(path, "rotate"), "rotation axis must not be zero"));
                }
                Quat::from_axis_angle(axis.as_vec3().normalize(), r.degrees.to_radians())
            }
        };
        let translation = Vec3::from(self.vec3(&with(path, "translate"), t.translate.unwrap_or(Fixed([0.0; 3])))?);
        Ok(Affine3A::from_scale_rotation_translation(scale, rotation, translation))
    }
}

fn with(path: &[Seg], key: &str) -> Vec<Seg> {
    let mut p = path.to_vec();
    p.push(Seg::Key(key.to_string()));
    p
}

fn with_index(path: &[Seg], i: usize) -> Vec<Seg> {
    let mut p = path.to_vec();
    p.push(Seg::Index(i));
    p
}

/// Reads and builds a scene file; see docs/scene-format.md.
pub fn load_scene(path: &Path) -> Result<SceneBuilder, LoadError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if matches!(ext.as_deref(), Some("gltf" | "glb")) {
        let g = super::gltf::load_gltf(path)?;
        g.messages.iter().for_each(|m| eprintln!("{m}"));
        return Ok(g.builder);
    }
    let file = path.display().to_string();
    let fail = |e: String| LoadError { file: file.clone(), position: None, field: String::new(), message: e };
    let bytes = super::read_regular_file(path).map_err(|e| fail(format!("cannot read scene file: {e}")))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        // Where the first bad byte is, as line and column.
        let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = valid.iter().filter(|&&b| b == b'\n').count() + 1;
        let column = valid.iter().rev().take_while(|&&b| b != b'\n').count() + 1;
        LoadError { position: Some((line, column)), ..fail("not UTF-8 text".to_string()) }
    })?;
    let dir = path.parent().unwrap_or(Path::new("."));
    parse_scene(&text, &file, dir)
}

/// Builds a scene from JSON text; `file` names it in errors and `dir`
/// resolves relative mesh paths.
pub fn parse_scene(text: &str, file: &str, dir: &Path) -> Result<SceneBuilder, LoadError> {
    // A UTF-8 byte order mark (some Windows editors write one) is not JSON;
    // without it, positions on the first line are the columns an editor shows.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let syntax = |field: String, e: serde_json::Error| LoadError {
        file: file.to_string(),
        // serde_json counts columns from 0 at the start of a line (e.g. at EOF there).
        position: (e.line() > 0).then(|| (e.line(), e.column().max(1))),
        field,
        message: strip_position(&e.to_string()),
    };
    let de = &mut serde_json::Deserializer::from_str(text);
    let parsed: SceneFile = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
        // serde_path_to_error writes `?` for a segment it could not name
        // (e.g. inside a syntax error); keep the part that is known.
        let field = e.path().to_string();
        let field = field.split(".?").next().unwrap_or_default().trim_end_matches('?').to_string();
        syntax(if field == "." { String::new() } else { field }, e.into_inner())
    })?;
    // Nothing but white space may follow the scene's object.
    de.end().map_err(|e| syntax(String::new(), e))?;
    let ctx = Ctx::new(file, text, dir, &parsed.spectra)?;
    build(&ctx, &parsed)
}

/// The id of the scene material `name`; `at` locates the reference.
fn material_id(ctx: &Ctx, ids: &BTreeMap<String, u32>, name: &str, at: &[Seg]) -> Result<u32, LoadError> {
    ids.get(name).copied().ok_or_else(|| {
        let known: Vec<&str> = ids.keys().map(String::as_str).collect();
        ctx.err(at, format!("unknown material \"{name}\" (known: {})", known.join(", ")))
    })
}

/// Adds a `gltf` shape's meshes and lights (src/scene/gltf.rs).
fn include_gltf(
    ctx: &Ctx,
    b: &mut SceneBuilder,
    path: &[Seg],
    name: &str,
    o: &ObjectSpec,
    g: &GltfSpec,
    ids: &BTreeMap<String, u32>,
) -> Result<(), LoadError> {
    let find = |name: &str, at: &[Seg]| material_id(ctx, ids, name, at);
    if o.emission.is_some() || o.two_sided {
        return Err(ctx.err(path, "emission and two_sided do not apply to a gltf shape (its emissive materials emit)"));
    }
    let shape = with(path, "shape");
    let material = o.material.as_deref().map(|m| find(m, &with(path, "material"))).transpose()?;
    let mut overrides = BTreeMap::new();
    for (key, name) in &g.materials {
        overrides.insert(key.clone(), find(name, &with(&with(&shape, "materials"), key))?);
    }
    let transform = match &o.transform {
        Some(t) => ctx.transform(&with(path, "transform"), t)?,
        None => Affine3A::IDENTITY,
    };
    super::gltf::include(b, &ctx.dir.join(&g.file), name, transform, material, &overrides).map_err(|e| match e.key {
        Some(key) => ctx.err(&with(&with(&shape, "materials"), &key), e.message),
        None => ctx.err(&with(&shape, "file"), e.message),
    })
}

/// serde_json appends " at line L column C"; we print the position up front.
pub(super) fn strip_position(msg: &str) -> String {
    match msg.rfind(" at line ") {
        Some(i) => msg[..i].to_string(),
        None => msg.to_string(),
    }
}

fn build(ctx: &Ctx, f: &SceneFile) -> Result<SceneBuilder, LoadError> {
    let mut b = SceneBuilder::new(camera(ctx, &f.camera)?);
    // Every entry of `spectra` is checked, used or not, as far as its form
    // allows without knowing its use (names and rgb depend on it; they are
    // checked where used).
    for (name, spec) in &f.spectra {
        if !matches!(spec, SpectrumSpec::Name(_) | SpectrumSpec::Rgb(..)) {
            ctx.spectrum(&[Seg::Key("spectra".into()), Seg::Key(name.clone())], spec, Use::Other)?;
        }
    }
    let mut material_ids = BTreeMap::new();
    for (name, spec) in &f.materials {
        let path = [Seg::Key("materials".into()), Seg::Key(name.clone())];
        let bsdf = ctx.material(&path, spec)?;
        material_ids.insert(name.clone(), b.material(name, bsdf));
    }
    objects(ctx, &mut b, &f.objects, &material_ids)?;
    lights(ctx, &mut b, &f.lights)?;
    b.defaults = render_defaults(ctx, &f.render)?;
    b.comment = f.comment.clone();
    Ok(b)
}

/// The pinhole camera of `camera`, each field checked.
fn camera(ctx: &Ctx, c: &CameraSpec) -> Result<Camera, LoadError> {
    let cam_path = [Seg::Key("camera".into())];
    let position = ctx.vec3(&with(&cam_path, "position"), c.position)?;
    let look_at = ctx.vec3(&with(&cam_path, "look_at"), c.look_at)?;
    let up = ctx.vec3(&with(&cam_path, "up"), c.up)?;
    if !(c.fov.is_finite() && c.fov > 0.0 && c.fov < 180.0) {
        return Err(ctx.err(&with(&cam_path, "fov"), "fov must be between 0 and 180 degrees"));
    }
    if let Err(e) = Camera::check_resolution(c.width, c.height) {
        // The field at fault: a zero height, else the width.
        let field = if c.height == 0 && c.width != 0 { "height" } else { "width" };
        return Err(ctx.err(&with(&cam_path, field), e));
    }
    if up == Vec3A::ZERO {
        return Err(ctx.err(&with(&cam_path, "up"), "up must not be zero"));
    }
    if Camera::frame(look_at.as_dvec3() - position.as_dvec3(), up.as_dvec3()).is_none() {
        return Err(ctx.err(&with(&cam_path, "look_at"), "look_at must differ from position and not be parallel to up"));
    }
    let camera = Camera::new(position, look_at, up, c.fov, c.width, c.height);
    if !camera.has_image_area() {
        return Err(ctx.err(&with(&cam_path, "fov"), format!("fov {:e} is too small: the image has no area", c.fov)));
    }
    Ok(camera)
}

/// Adds the `objects`: each shape as a mesh, transformed and checked.
fn objects(
    ctx: &Ctx,
    b: &mut SceneBuilder,
    objects: &[ObjectSpec],
    material_ids: &BTreeMap<String, u32>,
) -> Result<(), LoadError> {
    // Spheres first, by the triangles they declare: a line each, they
    // could otherwise fill the memory before the count is over.
    let mut declared = 0usize;
    for (i, o) in objects.iter().enumerate() {
        declared = declared.saturating_add(o.shape.declared_triangles());
        let path = with(&with_index(&[Seg::Key("objects".into())], i), "shape");
        check_triangle_count(declared).map_err(|e| ctx.err(&path, e))?;
    }
    for (i, o) in objects.iter().enumerate() {
        let path = with_index(&[Seg::Key("objects".into())], i);
        let name = o.name.clone().unwrap_or_else(|| format!("object {i}"));
        if let ShapeSpec::Gltf(g) = &o.shape {
            include_gltf(ctx, b, &path, &name, o, g, material_ids)?;
            continue;
        }
        let material = match &o.material {
            Some(m) => material_id(ctx, material_ids, m, &with(&path, "material"))?,
            None => return Err(ctx.err(&path, "missing field `material`")),
        };
        let mut mesh = ctx.shape(&with(&path, "shape"), &o.shape)?;
        if let ShapeSpec::Obj(obj) = &o.shape {
            b.inputs.push(ctx.dir.join(&obj.file));
        }
        if let Some(t) = &o.transform {
            mesh.transform(ctx.transform(&with(&path, "transform"), t)?);
        }
        let at = if o.transform.is_some() { with(&path, "transform") } else { with(&path, "shape") };
        if mesh.positions.iter().any(|p| !p.is_finite()) {
            return Err(ctx.err(&at, "vertex positions overflow the f32 range"));
        }
        mesh.check_f32_extent().map_err(|e| ctx.err(&at, e))?;
        check_triangle_count(b.triangle_count() + mesh.len()).map_err(|e| ctx.err(&with(&path, "shape"), e))?;
        let emission = match &o.emission {
            Some(e) => Some((ctx.radiance(&with(&path, "emission"), e)?, o.two_sided)),
            // Every BSDF scatters on both sides; the flag is the emitter's
            // (it was ignored without a word; a review, session 54).
            None if o.two_sided => {
                return Err(
                    ctx.err(&with(&path, "two_sided"), "applies to an emitter only (give the object an emission)")
                )
            }
            None => None,
        };
        b.mesh(&name, mesh, material, emission);
    }
    Ok(())
}

/// Adds the point and environment `lights`. The environment is what every
/// escaped ray sees, so a scene has one (as in Mitsuba); two would be half
/// seen and fully sampled.
fn lights(ctx: &Ctx, b: &mut SceneBuilder, lights: &[LightSpec]) -> Result<(), LoadError> {
    let mut environment = None;
    for (i, l) in lights.iter().enumerate() {
        let path = with_index(&[Seg::Key("lights".into())], i);
        match l {
            LightSpec::Point(p) => {
                let pos = ctx.vec3(&with(&path, "position"), p.position)?;
                let at = with(&path, "intensity");
                let intensity = ctx.spectrum(&at, &p.intensity, Use::Emission)?;
                super::check_intensity(&intensity).map_err(|why| ctx.err(&at, why))?;
                b.point_light(p.name.as_deref().unwrap_or("point light"), pos, intensity);
            }
            LightSpec::Environment(e) => {
                if let Some(first) = environment.replace(i) {
                    let message =
                        format!("a second environment light (lights[{first}] is one): add their radiances into one");
                    return Err(ctx.err(&path, message));
                }
                let le = ctx.radiance(&with(&path, "radiance"), &e.radiance)?;
                b.environment(e.name.as_deref().unwrap_or("environment"), le);
            }
        }
    }
    Ok(())
}

/// The `render` block: defaults that command-line flags override.
fn render_defaults(ctx: &Ctx, r: &RenderSpec) -> Result<RenderDefaults, LoadError> {
    if r.spp == Some(0) {
        return Err(ctx.err(&[Seg::Key("render".into()), Seg::Key("spp".into())], "spp must be at least 1"));
    }
    if let Some(name) = &r.integrator {
        if let Err(e) = crate::integrators::create(name, &Default::default()) {
            return Err(ctx.err(&[Seg::Key("render".into()), Seg::Key("integrator".into())], e));
        }
    }
    Ok(RenderDefaults {
        spp: r.spp,
        max_depth: r.max_depth,
        integrator: r.integrator.clone(),
        seed: r.seed.as_ref().map(|s| s.0),
    })
}
