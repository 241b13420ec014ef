//! The glTF 2.0 loader: `.gltf` (data-URI or external buffers) and `.glb`,
//! rendered directly (`prism render model.glb`) or included as one object of
//! a JSON scene (`{"type": "gltf", "file": ...}`).
//!
//! The mapping to the spectral BSDF library is documented in
//! docs/scene-format.md, section "glTF scenes"; in short:
//!
//! | glTF                                        | prism                                                     |
//! |---------------------------------------------|-----------------------------------------------------------|
//! | metallic >= 0.5                             | `Conductor`, eta and k fitted to the base colour (Gulbrandsen 2014) |
//! | metallic < 0.5, transmission >= 0.5         | `Dielectric`, ior from KHR_materials_ior (default 1.5)    |
//! | metallic < 0.5 otherwise                    | `Diffuse`, reflectance = base colour                      |
//! | roughness                                   | GGX alpha = roughness^2                                   |
//! | base colour (factor x texture mean)         | Jakob-Hanika reflectance spectrum (`rgb_albedo`)          |
//! | emissive (factor x strength x texture mean) | area light with `rgb_illuminant` radiance (D65-based)     |
//! | KHR_lights_punctual point (spot)            | point light, intensity = rgb_illuminant(colour) x candela |
//! | first perspective camera                    | pinhole camera (yfov, aspect ratio)                       |
//!
//! Textures are averaged (colours sRGB-decoded per texel first): the BSDFs
//! have no texture lookup, so a textured material renders with its mean and
//! the loader says so. What prism cannot represent is an error naming the
//! node or material (directional lights, sparse accessors, unsupported
//! required extensions) or a warning (points and lines, which have no area,
//! are skipped with one). Only what a path tracer has no use for passes
//! without a word: occlusion textures (it computes occlusion) and cameras'
//! clip planes; animations get a note.
//!
//! A material's `extras` may carry measured spectra that RGB cannot:
//! `"extras": {"prism": {"reflectance": S, "emission": S}}` with
//! S = `{"wavelengths": [...], "values": [...]}` (nm; piecewise linear with
//! the end values held, as in the JSON format). `reflectance` replaces the
//! base colour's spectrum, `emission` the emitted radiance (absolute: not
//! scaled by emissiveFactor or strength). scenes/gltf/cornell-box.gltf uses
//! them; any other glTF reader ignores them and sees the RGB values.

use super::locate::{locate, Seg};
use super::{check_triangle_count, LoadError, SceneBuilder};
use crate::camera::Camera;
use crate::materials::{roughness_to_alpha, Bsdf, Conductor, Dielectric, Diffuse};
use crate::shapes::Mesh;
use crate::spectrum::{self, Spectrum};
use glam::{Affine3A, DQuat, DVec3, Mat4, Vec3A};
use gltf::mesh::Mode;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// How far a node's rotation may be from unit length before it is
/// normalised with a warning. Files round their quaternions: the Khronos
/// sample `Cameras.gltf` writes (-0.383, 0, 0, 0.924), 2.3e-4 short, whose
/// matrix scales by less than 1e-3; nearer than this the crate's matrix is
/// used as it is.
const UNIT_QUATERNION_TOLERANCE: f64 = 1e-3;

/// Extensions whose data the loader reads; others are ignored with a
/// warning, or refused when the file requires them.
pub const SUPPORTED_EXTENSIONS: &[&str] =
    &["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_materials_ior", "KHR_materials_transmission"];

/// Image height for a glTF camera (glTF has no resolution; `prism render
/// --width/--height` override it); the width follows the aspect ratio, else
/// 4:3.
const DEFAULT_HEIGHT: u32 = 480;
const DEFAULT_ASPECT: f32 = 4.0 / 3.0;
/// Default framing when the file has no perspective camera: looking at the
/// centre of the bounding box from the +z side (glTF's front), 30 degrees
/// above the horizontal, up +y, so that the bounding sphere fits the image
/// height.
const DEFAULT_FOV_DEG: f32 = 40.0;
const DEFAULT_ELEVATION_DEG: f32 = 30.0;
/// Luminance of the constant D65 environment that lights a file with
/// neither punctual lights nor emissive materials.
const DEFAULT_ENVIRONMENT: f32 = 1.0;

/// A glTF file turned into a scene, with the warnings and notes the loader
/// made (each a full line, `warning: ...` or `note: ...`, for stderr).
pub struct GltfScene {
    pub builder: SceneBuilder,
    pub messages: Vec<String>,
}

/// Reads a `.gltf` or `.glb` file; external buffers and images are resolved
/// relative to its directory.
pub fn load_gltf(path: &Path) -> Result<GltfScene, LoadError> {
    let file = path.display().to_string();
    let bytes = super::read_regular_file(path).map_err(|e| LoadError {
        file: file.clone(),
        position: None,
        field: String::new(),
        message: format!("cannot read glTF file: {e}"),
    })?;
    parse_gltf(&bytes, &file, path.parent().unwrap_or(Path::new(".")))
}

/// Builds a scene from the bytes of a `.gltf` or `.glb` file; `file` names it
/// in messages and `dir` resolves external buffers and images.
pub fn parse_gltf(bytes: &[u8], file: &str, dir: &Path) -> Result<GltfScene, LoadError> {
    let mut imp = Importer::open(bytes, file, dir)?;
    let content = imp.import(Affine3A::IDENTITY, 0)?;
    let camera = match &content.camera {
        Some(c) => c.clone(),
        None => {
            imp.note("", "no perspective camera: default framing of the bounding box from +z, 30 degrees up");
            default_camera(&content.meshes).ok_or_else(|| {
                imp.fail("", "the scene is too large to frame a default camera in f32: give it a camera node")
            })?
        }
    };
    let mut b = SceneBuilder::new(camera);
    let ids = imp.add_materials(&mut b, &content, None, &BTreeMap::new());
    let mut emissive = false;
    let Content { meshes, lights, .. } = content;
    // Meshes move into the builder: a copy would double the scene's
    // geometry in memory until the import is dropped.
    for m in meshes {
        let emission = imp.materials[m.material].emission.clone();
        emissive |= emission.is_some();
        b.mesh(&m.name, m.mesh, ids[m.material], emission);
    }
    for (name, p, intensity) in &lights {
        b.point_light(name, *p, intensity.clone());
    }
    if lights.is_empty() && !emissive {
        imp.note(
            "",
            format!(
                "no punctual lights and no emissive materials: lit by a constant white (D65) environment of \
                 luminance {DEFAULT_ENVIRONMENT} (include the file in a JSON scene to choose other lights)"
            ),
        );
        let d65 = spectrum::illuminant("D65").expect("D65 is tabulated");
        b.environment("default environment", d65.scale(DEFAULT_ENVIRONMENT));
    }
    b.inputs.extend(imp.external_files());
    Ok(GltfScene { builder: b, messages: imp.messages })
}

/// Why including a glTF file in a JSON scene failed: `key` names the entry
/// of the object's `materials` map at fault, if any.
pub(super) struct IncludeError {
    pub key: Option<String>,
    pub message: String,
}

/// Adds the meshes, emissive materials and punctual lights of `path` to a
/// JSON scene under `transform` (the glTF's cameras are not used, nor is a
/// default environment added). `overrides` maps glTF material names (`#i`
/// for an unnamed material i) to prism material ids; `material`, if given,
/// replaces every glTF material not in `overrides`. An emissive glTF
/// material keeps emitting when its BSDF is overridden. Warnings go to
/// stderr.
pub(super) fn include(
    b: &mut SceneBuilder,
    path: &Path,
    object: &str,
    transform: Affine3A,
    material: Option<u32>,
    overrides: &BTreeMap<String, u32>,
) -> Result<(), IncludeError> {
    let err = |e: LoadError| IncludeError { key: None, message: e.to_string() };
    let file = path.display().to_string();
    let bytes = super::read_regular_file(path)
        .map_err(|e| IncludeError { key: None, message: format!("cannot read glTF file {file}: {e}") })?;
    let mut imp = Importer::open(&bytes, &file, path.parent().unwrap_or(Path::new("."))).map_err(err)?;
    let known: Vec<String> = imp.doc.materials().map(|m| material_key(&m)).collect();
    if let Some(key) = overrides.keys().find(|k| !known.contains(k)) {
        return Err(IncludeError {
            key: Some(key.clone()),
            message: format!("{file} has no material \"{key}\" (known: {})", known.join(", ")),
        });
    }
    imp.own_camera = false;
    let content = imp.import(transform, b.triangle_count()).map_err(err)?;
    if content.camera_nodes > 0 {
        imp.note("cameras", "not used: the including JSON scene's camera renders");
    }
    let ids = imp.add_materials(b, &content, material, overrides);
    let Content { meshes, lights, .. } = content;
    for m in meshes {
        let emission = imp.materials[m.material].emission.clone();
        b.mesh(&format!("{object}: {}", m.name), m.mesh, ids[m.material], emission);
    }
    for (name, p, intensity) in lights {
        b.point_light(&format!("{object}: {name}"), p, intensity);
    }
    for m in &imp.messages {
        eprintln!("{m}");
    }
    b.inputs.push(path.to_path_buf());
    b.inputs.extend(imp.external_files());
    Ok(())
}

/// What a glTF scene graph contributes, in world space.
struct Content {
    meshes: Vec<ImportedMesh>,
    /// (name, position, intensity) of each point light.
    lights: Vec<(String, Vec3A, Spectrum)>,
    camera: Option<Camera>,
    /// Nodes with a camera, the one used or not.
    camera_nodes: usize,
}

struct ImportedMesh {
    name: String,
    mesh: Mesh,
    /// Index into `Importer::materials`.
    material: usize,
}

/// A glTF material as prism sees it.
struct MappedMaterial {
    /// glTF material index; None for glTF's default material.
    index: Option<usize>,
    /// `materials[i] "name"` or `default material`, for messages.
    label: String,
    /// The name the JSON `materials` override map uses.
    key: String,
    emission: Option<(Spectrum, bool)>,
    /// The measured reflectance of `extras.prism`, if any (read once, with
    /// the emission, when the slot is made).
    reflectance: Option<Spectrum>,
}

struct Importer<'a> {
    file: String,
    /// The file's JSON text, if it is a `.gltf` (`json_text`).
    text: Option<&'a str>,
    /// Shared so that walking it while the importer changes is cheap.
    doc: Rc<gltf::Document>,
    buffers: Vec<Vec<u8>>,
    dir: PathBuf,
    /// The materials primitives use, in order of first use.
    materials: Vec<MappedMaterial>,
    material_slots: HashMap<Option<usize>, usize>,
    /// Texel means of each image (None: it could not be decoded).
    image_means: HashMap<usize, Option<ImageMeans>>,
    messages: Vec<String>,
    /// Whether the file's camera renders: false when a JSON scene includes
    /// it, and then its cameras are neither built nor checked.
    own_camera: bool,
}

/// What rendering without an extension the loader does not read means,
/// for its warning.
fn ignored_extension_effect(ext: &str) -> &'static str {
    match ext {
        // The volume extension declares meshes closed volumes, which prism
        // assumes of every transmissive material already.
        "KHR_materials_volume" => "transmissive meshes are solid volumes in prism anyway; the attenuation is not read",
        "KHR_materials_pbrSpecularGlossiness" => {
            "its materials take their metallic-roughness values, by default a rough white metal"
        }
        _ => "rendered as if it were absent",
    }
}

/// A UTF-8 byte-order mark, which glTF 2.0 forbids writers to emit and
/// allows readers to ignore.
const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// The text of a `.gltf` file, where its errors are located (a `.glb`
/// frames its JSON in binary chunks: its errors have no line).
fn json_text(bytes: &[u8]) -> Option<&str> {
    (!bytes.starts_with(b"glTF")).then(|| std::str::from_utf8(bytes).ok()).flatten()
}

/// An error at `field`, a label such as `meshes[0].primitives[1]` or
/// `nodes[2] "name"`: its path (up to the first space, when that holds an
/// index or is the whole label) is located in `text`.
fn load_error(file: &str, text: Option<&str>, field: &str, message: String) -> LoadError {
    let head = field.split(' ').next().unwrap_or_default().trim_end_matches(':');
    let path = (head.contains('[') || head == field).then(|| label_path(head)).flatten();
    let position = text.zip(path).map(|(t, p)| locate(t, &p));
    LoadError { file: file.to_string(), position, field: field.to_string(), message }
}

/// `a.b[1][2]` or `a["key"]` (the gltf crate's paths) as a JSON path;
/// None if it is not one. (A quoted key had none, so validation errors on
/// `attributes["POSITION"]` came without their line; from an audit,
/// session 50.)
fn label_path(label: &str) -> Option<Vec<Seg>> {
    let mut path = Vec::new();
    for part in label.split('.') {
        let mut pieces = part.split('[');
        let key =
            pieces.next().filter(|k| !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))?;
        path.push(Seg::Key(key.to_string()));
        for piece in pieces {
            let inner = piece.strip_suffix(']')?;
            path.push(match inner.strip_prefix('"').and_then(|k| k.strip_suffix('"')) {
                Some(key) => Seg::Key(key.to_string()),
                None => Seg::Index(inner.parse().ok()?),
            });
        }
    }
    Some(path)
}

impl<'a> Importer<'a> {
    fn open(bytes: &'a [u8], file: &str, dir: &Path) -> Result<Self, LoadError> {
        let bom = bytes.starts_with(UTF8_BOM);
        let bytes = bytes.strip_prefix(UTF8_BOM).unwrap_or(bytes);
        let text = json_text(bytes);
        let fail = |field: &str, message: String| load_error(file, text, field, message);
        let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| match e {
            // serde_json's position, where the scene loader puts it.
            gltf::Error::Deserialize(e) if text.is_some() => LoadError {
                file: file.to_string(),
                position: Some((e.line(), e.column())),
                field: String::new(),
                message: format!("not a valid glTF: {}", super::json::strip_position(&e.to_string())),
            },
            e => fail("", format!("not a valid glTF: {e}")),
        })?;
        let json = document.into_json();
        for (i, ext) in json.extensions_required.iter().enumerate() {
            if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                return Err(fail(
                    &format!("extensionsRequired[{i}]"),
                    format!(
                        "the file requires extension {ext}, which prism does not support (supported: {})",
                        SUPPORTED_EXTENSIONS.join(", ")
                    ),
                ));
            }
        }
        // gltf-json's validator reads each primitive's POSITION accessor
        // without a bounds check (gltf-json 1.4.1, mesh.rs:151): an index
        // out of range would panic there instead of being reported.
        for (m, mesh) in json.meshes.iter().enumerate() {
            for (p, primitive) in mesh.primitives.iter().enumerate() {
                let position = primitive
                    .attributes
                    .get(&gltf::json::validation::Checked::Valid(gltf::json::mesh::Semantic::Positions));
                if let Some(i) = position.filter(|i| i.value() >= json.accessors.len()) {
                    return Err(fail(
                        &format!("meshes[{m}].primitives[{p}].attributes.POSITION"),
                        format!("accessor {} does not exist ({} accessors)", i.value(), json.accessors.len()),
                    ));
                }
            }
        }
        let doc = gltf::Document::from_json(json).map_err(|e| match e {
            // The first fault the crate's validator found, at its path.
            gltf::Error::Validation(errors) if !errors.is_empty() => {
                let (path, error) = &errors[0];
                let more = match errors.len() {
                    1 => String::new(),
                    n => format!(" (and {} more)", n - 1),
                };
                fail(&path.to_string(), format!("invalid glTF: {}{more}", error.to_string().to_lowercase()))
            }
            e => fail("", e.to_string()),
        })?;
        let mut imp = Importer {
            file: file.to_string(),
            text,
            doc: Rc::new(doc),
            buffers: Vec::new(),
            dir: dir.to_path_buf(),
            materials: Vec::new(),
            material_slots: HashMap::new(),
            image_means: HashMap::new(),
            messages: Vec::new(),
            own_camera: true,
        };
        if bom {
            imp.warn("", "the file opens with a UTF-8 byte-order mark, which glTF writers must not emit: skipped");
        }
        let version = imp.doc.as_json().asset.version.clone();
        if !version.starts_with("2.") {
            imp.warn("asset.version", format!("version {version} is not glTF 2.x: read as glTF 2.0"));
        }
        // A file that needs a later glTF than 2.0 must not load in a 2.0
        // reader (glTF 2.0, "asset"; from an audit, session 50).
        if let Some(min) = imp.doc.as_json().asset.min_version.clone() {
            let digits = |d: &str| (!d.is_empty() && d.bytes().all(|c| c.is_ascii_digit())).then(|| d.parse().ok())?;
            match min.split_once('.').and_then(|(a, b)| Some((digits(a)?, digits(b)?))) {
                Some(v) if v > (2u32, 0u32) => {
                    let needs = format!("the file needs glTF {min}; prism reads glTF 2.0");
                    return Err(imp.fail("asset.minVersion", needs));
                }
                Some(_) => {}
                None => imp.warn("asset.minVersion", format!("\"{min}\" is not MAJOR.MINOR: ignored")),
            }
        }
        let used: Vec<String> = imp.doc.extensions_used().map(str::to_string).collect();
        for ext in used {
            if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                imp.warn("", format!("extension {ext} is ignored ({})", ignored_extension_effect(&ext)));
            }
        }
        let mut blob = blob;
        let mut buffers = Vec::new();
        for buffer in imp.doc.buffers() {
            let what = format!("buffers[{}]", buffer.index());
            let mut data = match buffer.source() {
                gltf::buffer::Source::Bin => {
                    let why = match imp.text {
                        Some(_) => "has no uri (only a .glb's first buffer may omit it)",
                        None => "the GLB has no binary chunk",
                    };
                    blob.take().ok_or_else(|| imp.fail(&what, why))?
                }
                gltf::buffer::Source::Uri(uri) => imp.read_uri(uri).map_err(|m| imp.fail(&what, m))?,
            };
            if data.len() < buffer.length() {
                return Err(imp.fail(&what, format!("holds {} bytes, byteLength says {}", data.len(), buffer.length())));
            }
            data.truncate(buffer.length());
            buffers.push(data);
        }
        imp.buffers = buffers;
        for view in imp.doc.views() {
            if view.offset().checked_add(view.length()).is_none_or(|end| end > view.buffer().length()) {
                return Err(imp.fail(&format!("bufferViews[{}]", view.index()), "lies outside its buffer"));
            }
        }
        Ok(imp)
    }

    /// The files the glTF file's buffers and images name (`read_uri`).
    fn external_files(&self) -> Vec<PathBuf> {
        let buffers = self.doc.buffers().filter_map(|b| match b.source() {
            gltf::buffer::Source::Uri(uri) => Some(uri),
            gltf::buffer::Source::Bin => None,
        });
        let images = self.doc.images().filter_map(|i| match i.source() {
            gltf::image::Source::Uri { uri, .. } => Some(uri),
            gltf::image::Source::View { .. } => None,
        });
        let files = buffers.chain(images).filter(|uri| !uri.contains(':'));
        files.map(|uri| self.dir.join(percent_decode(uri))).collect()
    }

    /// Bytes of a data URI or of a file relative to the glTF file.
    fn read_uri(&self, uri: &str) -> Result<Vec<u8>, String> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (_, data) = rest.split_once(";base64,").ok_or("only base64 data URIs are supported")?;
            return base64_decode(data).ok_or_else(|| "malformed base64 in data URI".to_string());
        }
        if uri.contains(':') {
            return Err(format!("unsupported URI \"{uri}\" (prism reads data: URIs and relative paths)"));
        }
        let path = self.dir.join(percent_decode(uri));
        super::read_regular_file(&path).map_err(|e| format!("cannot read {}: {e}", path.display()))
    }

    fn message(&mut self, kind: &str, what: &str, msg: impl Into<String>) {
        let what = if what.is_empty() { String::new() } else { format!("{what}: ") };
        self.messages.push(format!("{kind}: {}: {what}{}", self.file, msg.into()));
    }

    fn warn(&mut self, what: &str, msg: impl Into<String>) {
        self.message("warning", what, msg);
    }

    fn note(&mut self, what: &str, msg: impl Into<String>) {
        self.message("note", what, msg);
    }

    fn fail(&self, what: &str, message: impl Into<String>) -> LoadError {
        load_error(&self.file, self.text, what, message.into())
    }

    /// Walks the default scene (else the first) under `root`, depth first in
    /// node order; `used` triangles are already in the scene it joins.
    fn import(&mut self, root: Affine3A, used: usize) -> Result<Content, LoadError> {
        let nodes = self.walk(root)?;
        let doc = Rc::clone(&self.doc);
        self.check_triangles(&nodes, used)?;
        let mut content = Content { meshes: Vec::new(), lights: Vec::new(), camera: None, camera_nodes: 0 };
        for (index, world) in nodes {
            let node = doc.nodes().nth(index).expect("validated node index");
            let label = label("nodes", index, node.name());
            if let Some(mesh) = node.mesh() {
                self.import_mesh(&node, &mesh, world, &label, &mut content)?;
            }
            if node.skin().is_some() {
                self.warn(
                    &label,
                    "skinning is ignored: the mesh is placed by its node's transform in its stored shape (glTF places \
                     a skinned mesh by its joints alone; the two agree when the skeleton rests in its bind pose)",
                );
            }
            if let Some(camera) = node.camera() {
                content.camera_nodes += 1;
                match camera.projection() {
                    // (An included file's cameras are not used, nor checked:
                    // a degenerate one failed the include; from an audit,
                    // session 50.)
                    _ if !self.own_camera => {}
                    gltf::camera::Projection::Perspective(p) if content.camera.is_none() => {
                        content.camera = Some(self.camera(&label, world, p.yfov(), p.aspect_ratio())?);
                        self.note(&label, "renders through this node's camera");
                    }
                    gltf::camera::Projection::Perspective(_) => {}
                    gltf::camera::Projection::Orthographic(_) => {
                        self.warn(&label, "orthographic camera ignored (prism has a pinhole camera only)");
                    }
                }
            }
            if let Some(light) = node.light() {
                self.import_light(&light, world, &label, &mut content)?;
            }
        }
        if content.camera_nodes > 1 && content.camera.is_some() {
            self.note("cameras", format!("{} other camera node(s) not used", content.camera_nodes - 1));
        }
        if content.meshes.is_empty() {
            self.warn("scenes", "the scene has no surfaces to render");
        }
        let animations = doc.animations().count();
        if animations > 0 {
            self.note("animations", format!("{animations} animation(s) ignored: the static pose is rendered"));
        }
        Ok(content)
    }

    /// The nodes of the default scene (else the first), depth first in node
    /// order, with their world transforms under `root`.
    fn walk(&mut self, root: Affine3A) -> Result<Vec<(usize, Affine3A)>, LoadError> {
        let scene_count = self.doc.scenes().count();
        let scene = self.doc.default_scene().or_else(|| self.doc.scenes().next()).map(|s| s.index());
        let Some(scene) = scene else {
            return Err(self.fail("scenes", "the file has no scene to render"));
        };
        if scene_count > 1 {
            self.note("scenes", format!("renders scene {scene} of {scene_count}"));
        }
        let doc = Rc::clone(&self.doc);
        let roots = doc.scenes().nth(scene).expect("scene index").nodes();
        // glTF 2.0, 3.5.3: the nodes form disjoint trees, so a walk meets
        // each node once (a node met again would be a cycle, or a walk that
        // grows as 2^depth).
        let mut reached = vec![false; doc.nodes().len()];
        let mut nodes = Vec::new();
        let mut stack: Vec<(gltf::Node, Affine3A)> = roots.map(|n| (n, root)).collect();
        stack.reverse();
        while let Some((node, parent)) = stack.pop() {
            let label = label("nodes", node.index(), node.name());
            if std::mem::replace(&mut reached[node.index()], true) {
                return Err(self.fail(&label, "the node is reached twice: glTF nodes form disjoint trees"));
            }
            let local = self.node_transform(&node, &label)?;
            let world = parent * local;
            if !world.is_finite() {
                return Err(self.fail(&label, "the node transform is not finite"));
            }
            nodes.push((node.index(), world));
            stack.extend(node.children().map(|c| (c, world)).collect::<Vec<_>>().into_iter().rev());
        }
        Ok(nodes)
    }

    /// A node's local transform, with warnings of what glTF 2.0 (5.25,
    /// "node") forbids in it and the loader would otherwise read without a
    /// word: TRS beside a matrix (the matrix is used), a matrix whose last
    /// row is not (0, 0, 0, 1) (an affine transform is used), and a rotation
    /// that is not a unit quaternion (normalised: the crate's matrix of it
    /// assumes unit length, and would turn the mesh by another angle and
    /// scale it across the axis; a zero or non-finite one is an error).
    fn node_transform(&mut self, node: &gltf::Node, label: &str) -> Result<Affine3A, LoadError> {
        let json = &self.doc.as_json().nodes[node.index()];
        let (matrix, rotation) = (json.matrix, json.rotation.as_ref().map(|r| r.0));
        let trs = json.translation.or(json.scale).is_some() || rotation.is_some();
        let given = Affine3A::from_mat4(Mat4::from_cols_array_2d(&node.transform().matrix()));
        let Some(m) = matrix else {
            let Some(r) = rotation else { return Ok(given) };
            // In f64, where the squares of f32 neither overflow nor underflow.
            let q = DQuat::from_array(r.map(f64::from));
            let length = q.length();
            if (length - 1.0).abs() <= UNIT_QUATERNION_TOLERANCE {
                return Ok(given);
            }
            if !(length.is_finite() && length > 0.0) {
                return Err(self.fail(label, format!("rotation {r:?} is zero or not finite: not a rotation")));
            }
            self.warn(label, format!("rotation {r:?} is not a unit quaternion (length {length:.6}): normalised"));
            let (t, _, s) = node.transform().decomposed();
            return Ok(Affine3A::from_scale_rotation_translation(s.into(), (q / length).as_quat(), t.into()));
        };
        if trs {
            self.warn(label, "the node has a matrix and translation, rotation or scale: the matrix is used");
        }
        let row = [m[3], m[7], m[11], m[15]];
        if row != [0.0, 0.0, 0.0, 1.0] {
            self.warn(
                label,
                format!("the matrix's last row {row:?} is not [0, 0, 0, 1]: dropped (an affine transform is used)"),
            );
        }
        Ok(given)
    }

    /// The triangles the nodes' meshes declare (by their accessors' counts,
    /// before any is read), with `used` more, within `MAX_TRIANGLES`: a
    /// small file may instance one large mesh many times.
    fn check_triangles(&self, nodes: &[(usize, Affine3A)], used: usize) -> Result<(), LoadError> {
        let mut total = used;
        for &(index, _) in nodes {
            let node = self.doc.nodes().nth(index).expect("validated node index");
            let Some(mesh) = node.mesh() else { continue };
            total = mesh.primitives().map(|p| declared_triangles(&p)).fold(total, usize::saturating_add);
            check_triangle_count(total).map_err(|e| self.fail(&label("nodes", index, node.name()), e))?;
        }
        Ok(())
    }

    fn camera(&mut self, label: &str, world: Affine3A, yfov: f32, aspect: Option<f32>) -> Result<Camera, LoadError> {
        let position = world.translation;
        let (forward, up) = (world.transform_vector3a(-Vec3A::Z), world.transform_vector3a(Vec3A::Y));
        let (forward, up) = (forward.as_dvec3(), up.as_dvec3());
        if Camera::frame(forward, up).is_none() {
            return Err(self.fail(label, "the camera's transform is degenerate (no view or up direction)"));
        }
        if let Some(why) = camera_distortion(&world) {
            let what = format!("the camera's transform {why}: rendered from its position, -z and +y alone");
            self.warn(label, what);
        }
        let fov = yfov.to_degrees();
        if !(fov.is_finite() && fov > 0.0 && fov < 180.0) {
            return Err(self.fail(label, format!("yfov {yfov} rad is not between 0 and pi")));
        }
        let valid = aspect.filter(|a| a.is_finite() && *a > 0.0);
        if let Some(a) = aspect.filter(|_| valid.is_none()) {
            return Err(self.fail(label, format!("aspectRatio {a} is not a positive number")));
        }
        let aspect = valid.unwrap_or(DEFAULT_ASPECT);
        let exact = (DEFAULT_HEIGHT as f32 * aspect).round();
        let width = (exact as u32).clamp(1, 16384);
        if !(1.0..=16384.0).contains(&exact) {
            let why = format!("aspectRatio {aspect} at {DEFAULT_HEIGHT} rows: the width is clamped to {width} pixels");
            self.warn(label, why);
        }
        let camera = Camera::looking(position, forward, up, fov, width, DEFAULT_HEIGHT);
        // As the JSON loader: light tracing divides by the image's area.
        if !camera.has_image_area() {
            return Err(self.fail(label, format!("yfov {yfov:e} rad is too small: the image has no area")));
        }
        Ok(camera)
    }

    fn import_light(
        &mut self,
        light: &gltf::khr_lights_punctual::Light,
        world: Affine3A,
        label: &str,
        content: &mut Content,
    ) -> Result<(), LoadError> {
        use gltf::khr_lights_punctual::Kind;
        let name = light.name().map_or_else(|| label.to_string(), str::to_string);
        match light.kind() {
            Kind::Point => {}
            Kind::Spot { .. } => {
                self.warn(label, format!("spot light \"{name}\" rendered as a point light (its cone is ignored)"));
            }
            Kind::Directional => {
                return Err(self.fail(
                    label,
                    format!(
                        "directional light \"{name}\" is not supported: prism has no directional light (remove \
                         it from the file; a JSON scene that includes the file can light it with an environment)"
                    ),
                ));
            }
        }
        if light.range().is_some() {
            self.warn(label, format!("light \"{name}\": range is ignored (point lights fall off as 1/r^2)"));
        }
        let color = light.color();
        let intensity = light.intensity();
        if !(color.iter().all(|c| c.is_finite() && *c >= 0.0) && intensity.is_finite() && intensity >= 0.0) {
            return Err(self.fail(label, format!("light \"{name}\": colour and intensity must be finite and >= 0")));
        }
        // KHR_lights_punctual: the intensity (candela) is that of the light
        // coloured white; the colour multiplies it per channel, so a pure
        // red light has the luminance of the red primary times intensity.
        let spectrum = spectrum::rgb_illuminant(color).scale(intensity);
        self.check_emission(&format!("{label}: light \"{name}\""), &spectrum)?;
        super::check_intensity(&spectrum).map_err(|why| {
            self.fail(label, format!("light \"{name}\": its spectrum (colour x intensity) as an intensity {why}"))
        })?;
        content.lights.push((name, world.translation, spectrum));
        Ok(())
    }

    fn import_mesh(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        world: Affine3A,
        node_label: &str,
        content: &mut Content,
    ) -> Result<(), LoadError> {
        let what = format!("{node_label} ({})", label("meshes", mesh.index(), mesh.name()));
        // glTF allows a zero scale (an object hidden by animation), but a
        // still scene shows nothing of such a mesh (a review, session 53).
        if world.matrix3.determinant() == 0.0 {
            self.warn(&what, "the node's transform is singular (a scale of 0): its mesh has no area and is not seen");
        }
        if node.weights().is_some() || mesh.weights().is_some() {
            self.warn(&what, "morph target weights are ignored: the base shape is rendered");
        }
        if mesh.primitives().len() == 0 {
            self.warn(&what, "the mesh has no primitives (glTF requires one): nothing to render");
        }
        for prim in mesh.primitives() {
            let pwhat = format!("{what}, primitive {}", prim.index());
            if !matches!(prim.mode(), Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                let why = format!("mode {:?} has no area: skipped (prism renders surfaces)", prim.mode());
                self.warn(&pwhat, why);
                continue;
            }
            self.check_primitive(&prim, &pwhat)?;
            let mut m = self.read_primitive(&prim, &pwhat)?;
            // Before the transform, which makes a NaN normal zero (flat).
            if m.normals.iter().any(|n| !n.is_finite()) {
                return Err(self.fail(&pwhat, "NORMAL values are not finite"));
            }
            m.transform(world);
            if m.positions.iter().any(|p| !p.is_finite()) {
                return Err(self.fail(&pwhat, "vertex positions are not finite"));
            }
            m.check_f32_extent().map_err(|e| self.fail(&pwhat, e))?;
            let material = self.material_slot(&prim.material())?;
            content.meshes.push(ImportedMesh { name: pwhat, mesh: m, material });
        }
        Ok(())
    }

    /// A surface primitive's accessor layouts: those the crate's readers
    /// assume (they panic or misread otherwise).
    fn check_primitive(&mut self, prim: &gltf::Primitive, pwhat: &str) -> Result<(), LoadError> {
        use gltf::accessor::{DataType, Dimensions};
        let layout = |a: &gltf::Accessor, dims: Dimensions, types: &[DataType]| {
            a.dimensions() == dims && types.contains(&a.data_type())
        };
        if let Some(a) = prim.get(&gltf::Semantic::Positions) {
            if !layout(&a, Dimensions::Vec3, &[DataType::F32]) {
                return Err(self.fail(pwhat, "POSITION must be VEC3 of FLOAT (quantized positions unsupported)"));
            }
        }
        if let Some(a) = prim.get(&gltf::Semantic::Normals) {
            if !layout(&a, Dimensions::Vec3, &[DataType::F32]) {
                return Err(self.fail(pwhat, "NORMAL must be VEC3 of FLOAT (quantized normals unsupported)"));
            }
        }
        if let Some(a) = prim.indices() {
            if !layout(&a, Dimensions::Scalar, &[DataType::U8, DataType::U16, DataType::U32]) {
                return Err(self.fail(pwhat, "indices must be SCALAR of UNSIGNED_BYTE, _SHORT or _INT"));
            }
            // glTF 2.0, 3.6.2.4: only vertex attributes have a stride; a
            // reader that ignores one on indices winds other triangles.
            if let Some(view) = a.view().filter(|v| v.stride().is_some()) {
                let why = format!(
                    "bufferViews[{}] of the indices has a byteStride (only vertex attributes may)",
                    view.index()
                );
                return Err(self.fail(pwhat, why));
            }
        }
        if prim.attributes().any(|(s, _)| s == gltf::Semantic::Colors(0)) {
            self.warn(pwhat, "vertex colours (COLOR_0) are ignored");
        }
        Ok(())
    }

    /// A primitive's triangles in its local frame: positions, normals (when
    /// there is one per position) and the triangulated index list, each
    /// accessor checked against its buffer.
    fn read_primitive(&mut self, prim: &gltf::Primitive, pwhat: &str) -> Result<Mesh, LoadError> {
        let accessors = [prim.get(&gltf::Semantic::Positions), prim.get(&gltf::Semantic::Normals), prim.indices()];
        for a in accessors.iter().flatten() {
            check_layout(a).map_err(|m| self.fail(pwhat, format!("accessors[{}]: {m}", a.index())))?;
        }
        let (positions, normals, list) = {
            let buffers = &self.buffers;
            let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let positions: Option<Vec<Vec3A>> = reader.read_positions().map(|p| p.map(Vec3A::from_array).collect());
            let normals: Vec<Vec3A> =
                reader.read_normals().map_or_else(Vec::new, |n| n.map(Vec3A::from_array).collect());
            let list: Option<Vec<u32>> = reader.read_indices().map(|i| i.into_u32().collect());
            (positions, normals, list)
        };
        let Some(positions) = positions else {
            let why = match prim.get(&gltf::Semantic::Positions) {
                Some(_) => "its POSITION accessor gives no data (no buffer view, or one its buffer is too short for)",
                None => "has no POSITION data",
            };
            return Err(self.fail(pwhat, why));
        };
        let normals = if normals.len() == positions.len() {
            normals
        } else {
            if !normals.is_empty() {
                self.warn(pwhat, "NORMAL count differs from POSITION count: flat shading");
            }
            Vec::new()
        };
        // `check_layout` made each accessor read exactly `count` elements.
        let list = list.unwrap_or_else(|| (0..positions.len() as u32).collect());
        // glTF 2.0, 3.7.2.1: TRIANGLES takes the vertices three at a time;
        // the rest make no triangle (a warning, as the Khronos validator's
        // MESH_PRIMITIVE_INCOMPATIBLE_MODE is).
        if prim.mode() == Mode::Triangles && list.len() % 3 != 0 {
            let n = list.len();
            self.warn(
                pwhat,
                format!("{n} vertices do not make whole triangles (mode Triangles): the last {} are ignored", n % 3),
            );
        }
        if matches!(prim.mode(), Mode::TriangleStrip | Mode::TriangleFan) && list.len() < 3 {
            let why = format!("{} vertices make no triangle (mode {:?})", list.len(), prim.mode());
            self.warn(pwhat, why);
        }
        if let Some(i) = list.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(self.fail(pwhat, format!("index {i} is out of range ({} positions)", positions.len())));
        }
        Ok(Mesh { positions, normals, indices: triangulate(prim.mode(), &list) })
    }

    /// The slot of a glTF material, created (with its emission) on first use.
    fn material_slot(&mut self, m: &gltf::Material) -> Result<usize, LoadError> {
        if let Some(&slot) = self.material_slots.get(&m.index()) {
            return Ok(slot);
        }
        let label = m.index().map_or_else(|| "default material".to_string(), |i| label("materials", i, m.name()));
        let extras = self.prism_extras(m, &label)?;
        let emission = self.emission(m, &label, extras.emission)?;
        let reflectance = extras.reflectance;
        self.materials.push(MappedMaterial { index: m.index(), label, key: material_key(m), emission, reflectance });
        let slot = self.materials.len() - 1;
        self.material_slots.insert(m.index(), slot);
        Ok(slot)
    }

    /// Adds the BSDFs of the used materials to `b` (unless overridden);
    /// returns the material id of each slot.
    fn add_materials(
        &mut self,
        b: &mut SceneBuilder,
        content: &Content,
        material: Option<u32>,
        overrides: &BTreeMap<String, u32>,
    ) -> Vec<u32> {
        let mut ids = vec![0; self.materials.len()];
        for (slot, id) in ids.iter_mut().enumerate() {
            if !content.meshes.iter().any(|m| m.material == slot) {
                continue;
            }
            if let Some(&o) = overrides.get(&self.materials[slot].key).or(material.as_ref()) {
                *id = o;
                continue;
            }
            let doc = Rc::clone(&self.doc);
            let gm = match self.materials[slot].index {
                Some(i) => doc.materials().nth(i).expect("validated material index"),
                None => default_material(&doc),
            };
            let (label, measured) = (self.materials[slot].label.clone(), self.materials[slot].reflectance.clone());
            let bsdf = self.bsdf(&gm, &label, measured);
            *id = b.material(&self.materials[slot].key, bsdf);
        }
        ids
    }

    /// The BSDF of a glTF material (rules in the module header); `measured`
    /// is its `extras.prism` reflectance, which replaces the base colour's.
    fn bsdf(&mut self, m: &gltf::Material, label: &str, measured: Option<Spectrum>) -> Bsdf {
        let pbr = m.pbr_metallic_roughness();
        let factors = [
            ("baseColorFactor", &pbr.base_color_factor()[..]),
            ("metallicFactor", &[pbr.metallic_factor()][..]),
            ("roughnessFactor", &[pbr.roughness_factor()][..]),
        ];
        for (name, values) in factors {
            if !values.iter().all(|v| (0.0..=1.0).contains(v)) {
                self.warn(label, format!("{name} {values:?} is outside [0, 1] (invalid glTF): clamped"));
            }
        }
        // Clamped before a texture's mean multiplies them (an infinite
        // factor times a mean of 0 would be NaN).
        let mut base = pbr.base_color_factor().map(|c| c.clamp(0.0, 1.0));
        if let Some(info) = pbr.base_color_texture() {
            if let Some(mean) = self.texture_mean(&info.texture(), true, label, "baseColorTexture") {
                for c in 0..4 {
                    base[c] *= mean[c];
                }
            }
        }
        let [mut metallic, mut roughness] = [pbr.metallic_factor(), pbr.roughness_factor()].map(|f| f.clamp(0.0, 1.0));
        if let Some(info) = pbr.metallic_roughness_texture() {
            if let Some(mean) = self.texture_mean(&info.texture(), false, label, "metallicRoughnessTexture") {
                roughness *= mean[1];
                metallic *= mean[2];
            }
        }
        if m.alpha_mode() != gltf::material::AlphaMode::Opaque {
            self.warn(label, format!("alphaMode {:?} is ignored: rendered opaque", m.alpha_mode()));
        }
        if m.normal_texture().is_some() {
            self.warn(label, "normalTexture is ignored (the BSDFs have no texture lookup)");
        }
        let rgb = [base[0], base[1], base[2]];
        let reflectance = measured.unwrap_or_else(|| spectrum::rgb_albedo(rgb));
        let alpha = roughness_to_alpha(roughness);
        if metallic > 0.0 && metallic < 1.0 {
            let choice = if metallic >= 0.5 { "a conductor" } else { "a non-metal" };
            self.warn(label, format!("metallic {metallic} is neither 0 nor 1: rendered as {choice} (threshold 0.5)"));
        }
        if metallic >= 0.5 {
            return conductor_from_f0(&reflectance, alpha);
        }
        let mut transmission = 0.0;
        if let Some(t) = m.transmission() {
            if t.transmission_texture().is_some() {
                self.warn(label, "transmissionTexture is ignored (the factor alone decides)");
            }
            transmission = t.transmission_factor();
        }
        if transmission > 0.0 && transmission < 1.0 {
            let choice = if transmission >= 0.5 { "a dielectric" } else { "diffuse" };
            self.warn(
                label,
                format!("transmission {transmission} is neither 0 nor 1: rendered {choice} (threshold 0.5)"),
            );
        }
        if transmission >= 0.5 {
            let mut ior = m.ior().unwrap_or(1.5);
            if !(ior.is_finite() && ior >= 1.0) {
                self.warn(label, format!("ior {ior} is not >= 1: 1.5 used"));
                ior = 1.5;
            }
            if rgb != [1.0; 3] {
                self.warn(label, "the base colour does not tint transmission in prism (a clear dielectric)");
            }
            let mut dielectric = Dielectric::new(Spectrum::Constant(ior), alpha, alpha);
            if dielectric.index_unresolved() {
                self.warn(
                    label,
                    format!(
                        "ior {ior} is too near 1 for a rough surface (it must differ from 1 by {}): f32 cannot \
                         resolve its refraction, a smooth interface used",
                        dielectric.min_index_contrast_text()
                    ),
                );
                dielectric = Dielectric::new(Spectrum::Constant(ior), 0.0, 0.0);
            }
            return Bsdf::Dielectric(dielectric);
        }
        Bsdf::Diffuse(Diffuse::new(reflectance))
    }

    /// Emitted radiance: the prism extras' spectrum, else emissiveFactor x
    /// emissiveStrength x the emissive texture's mean as an RGB illuminant;
    /// two-sided when the material is double-sided.
    fn emission(
        &mut self,
        m: &gltf::Material,
        label: &str,
        measured: Option<Spectrum>,
    ) -> Result<Option<(Spectrum, bool)>, LoadError> {
        if let Some(s) = measured {
            super::check_radiance(&s).map_err(|why| self.fail(label, format!("the emitted radiance {why}")))?;
            return Ok((s.max_value() > 0.0).then_some((s, m.double_sided())));
        }
        let strength = m.emissive_strength().unwrap_or(1.0);
        if m.emissive_factor().iter().any(|&c| c > 1.0) {
            let why = format!(
                "emissiveFactor {:?} is above 1 (invalid glTF; KHR_materials_emissive_strength is the valid way): used as given",
                m.emissive_factor()
            );
            self.warn(label, why);
        }
        let mut rgb = m.emissive_factor().map(|c| c * strength);
        if rgb.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(self.fail(label, "emissiveFactor x emissiveStrength must be finite and >= 0"));
        }
        if rgb == [0.0; 3] {
            return Ok(None);
        }
        if let Some(info) = m.emissive_texture() {
            if let Some(mean) = self.texture_mean(&info.texture(), true, label, "emissiveTexture") {
                for c in 0..3 {
                    rgb[c] *= mean[c];
                }
            }
        }
        if rgb == [0.0; 3] {
            return Ok(None);
        }
        let s = spectrum::rgb_illuminant(rgb);
        self.check_emission(label, &s)?;
        super::check_radiance(&s).map_err(|why| self.fail(label, format!("the emitted radiance {why}")))?;
        Ok(Some((s, m.double_sided())))
    }

    /// An emitted spectrum must be finite: an infinite one makes the
    /// scene's light power infinite, leaving no light to sample.
    fn check_emission(&self, label: &str, s: &Spectrum) -> Result<(), LoadError> {
        match s.is_finite() {
            true => Ok(()),
            false => Err(self.fail(label, "the emitted spectrum is not finite at every wavelength (overflow)")),
        }
    }

    /// The material's `extras.prism` spectra, if any.
    fn prism_extras(&self, m: &gltf::Material, label: &str) -> Result<PrismExtras, LoadError> {
        let Some(raw) = m.extras() else { return Ok(PrismExtras::default()) };
        let at = format!("{label}: extras.prism");
        let value: serde_json::Value =
            serde_json::from_str(raw.get()).map_err(|e| self.fail(&at, format!("not JSON: {e}")))?;
        let Some(prism) = value.get("prism") else { return Ok(PrismExtras::default()) };
        let obj = prism.as_object().ok_or_else(|| self.fail(&at, "must be an object"))?;
        if let Some(k) = obj.keys().find(|k| *k != "reflectance" && *k != "emission") {
            return Err(self.fail(&at, format!("unknown field \"{k}\" (expected reflectance, emission)")));
        }
        let spectrum = |key: &str, max: Option<f32>| -> Result<Option<Spectrum>, LoadError> {
            obj.get(key).map(|v| tabulated(v, max).map_err(|msg| self.fail(&format!("{at}.{key}"), msg))).transpose()
        };
        Ok(PrismExtras { reflectance: spectrum("reflectance", Some(1.0))?, emission: spectrum("emission", None)? })
    }

    /// Mean of a texture's image (RGBA in [0, 1]; colour channels
    /// sRGB-decoded per texel when `srgb`), with a warning that the mean
    /// stands for the texture; None, with a warning, if the image cannot be
    /// decoded.
    fn texture_mean(&mut self, tex: &gltf::Texture, srgb: bool, label: &str, slot: &str) -> Option<[f32; 4]> {
        let image = tex.source();
        let index = image.index();
        if !self.image_means.contains_key(&index) {
            let means = match self.decode(&image) {
                Ok(m) => Some(m),
                Err(msg) => {
                    self.warn(label, format!("{slot}: {msg}; the factor alone is used"));
                    None
                }
            };
            self.image_means.insert(index, means);
        }
        let m = self.image_means[&index]?;
        let rgb = if srgb { m.srgb } else { m.linear };
        let shown = rgb.map(|v| (v * 1000.0).round() / 1000.0);
        self.warn(label, format!("{slot} is replaced by its mean {shown:?} (the BSDFs have no texture lookup)"));
        Some([rgb[0], rgb[1], rgb[2], m.alpha])
    }

    /// Decodes a PNG image (prism's image crate is built without JPEG).
    fn decode(&self, image: &gltf::image::Image) -> Result<ImageMeans, String> {
        let bytes = match image.source() {
            gltf::image::Source::View { view, .. } => {
                let data = &self.buffers[view.buffer().index()];
                data[view.offset()..view.offset() + view.length()].to_vec()
            }
            gltf::image::Source::Uri { uri, .. } => self.read_uri(uri)?,
        };
        if !bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            let kind = if bytes.starts_with(&[0xFF, 0xD8]) { "a JPEG" } else { "not a PNG" };
            return Err(format!("image {} is {kind}: prism decodes PNG only", image.index()));
        }
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
            .map_err(|e| format!("image {}: {e}", image.index()))?
            .to_rgba8();
        Ok(ImageMeans::of(img.as_raw()))
    }
}

/// Texel means of an image, in [0, 1]: colour channels as stored
/// (`linear`) and sRGB-decoded per texel (`srgb`), and alpha.
#[derive(Clone, Copy)]
struct ImageMeans {
    srgb: [f32; 3],
    linear: [f32; 3],
    alpha: f32,
}

impl ImageMeans {
    fn of(rgba: &[u8]) -> Self {
        let decode: Vec<f64> = (0..256).map(|v| srgb_to_linear(v as f64 / 255.0)).collect();
        let n = (rgba.len() / 4).max(1) as f64;
        let (mut srgb, mut linear, mut alpha) = ([0f64; 3], [0f64; 3], 0f64);
        for t in rgba.chunks_exact(4) {
            for c in 0..3 {
                srgb[c] += decode[t[c] as usize];
                linear[c] += t[c] as f64 / 255.0;
            }
            alpha += t[3] as f64 / 255.0;
        }
        Self { srgb: srgb.map(|v| (v / n) as f32), linear: linear.map(|v| (v / n) as f32), alpha: (alpha / n) as f32 }
    }
}

/// The sRGB transfer function, decoded (IEC 61966-2-1).
fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Spectra a material's `extras.prism` may give.
#[derive(Default)]
struct PrismExtras {
    reflectance: Option<Spectrum>,
    emission: Option<Spectrum>,
}

/// A `{"wavelengths": [...], "values": [...]}` spectrum with values in
/// [0, `max`].
fn tabulated(v: &serde_json::Value, max: Option<f32>) -> Result<Spectrum, String> {
    let obj = v.as_object().ok_or("expected {\"wavelengths\": [...], \"values\": [...]}")?;
    if let Some(k) = obj.keys().find(|k| *k != "wavelengths" && *k != "values") {
        return Err(format!("unknown field \"{k}\" (expected wavelengths, values)"));
    }
    let arr = |k: &str| -> Result<Vec<f32>, String> {
        obj.get(k)
            .and_then(|a| a.as_array())
            .and_then(|a| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect::<Option<Vec<f32>>>())
            .ok_or_else(|| format!("\"{k}\" must be an array of numbers"))
    };
    let (w, vals) = (arr("wavelengths")?, arr("values")?);
    if w.is_empty() || w.len() != vals.len() {
        return Err("\"wavelengths\" and \"values\" must be non-empty and of equal length".into());
    }
    if w.iter().chain(&vals).any(|x| !x.is_finite()) || w.windows(2).any(|p| p[1] <= p[0]) {
        return Err("numbers must be finite and the wavelengths strictly increasing".into());
    }
    if w[0] <= 0.0 {
        return Err("\"wavelengths\" are in nanometres, all above 0".into());
    }
    if vals.iter().any(|&x| x < 0.0 || max.is_some_and(|m| x > m)) {
        return Err(format!("values must lie in [0, {}]", max.map_or("inf".to_string(), |m| m.to_string())));
    }
    let pts: Vec<(f32, f32)> = w.into_iter().zip(vals).collect();
    Ok(Spectrum::piecewise_linear(&pts))
}

/// glTF's default material (spec 3.9.6: white, metallic 1, roughness 1), as
/// the crate gives it to a primitive without a material.
fn default_material(doc: &gltf::Document) -> gltf::Material<'_> {
    doc.meshes()
        .flat_map(|m| m.primitives().map(|p| p.material()).collect::<Vec<_>>())
        .find(|m| m.index().is_none())
        .expect("the default material is only mapped for a primitive without a material")
}

/// The name a JSON `materials` override map uses for a glTF material: its
/// name, else `#index`.
fn material_key(m: &gltf::Material) -> String {
    match (m.name(), m.index()) {
        (Some(n), _) if !n.is_empty() => n.to_string(),
        (_, Some(i)) => format!("#{i}"),
        (_, None) => "default".to_string(),
    }
}

fn label(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) if !n.is_empty() => format!("{kind}[{index}] \"{n}\""),
        _ => format!("{kind}[{index}]"),
    }
}

/// What the `gltf` crate's reader assumes of an accessor and panics on
/// otherwise (glTF 2.0 spec 3.6.2.4, "Data Alignment", and 5.1 "accessor"):
/// at least one element, a buffer view stride no shorter than the element,
/// and its elements inside the view. Sparse accessors are refused: their
/// indices would have to be checked against `count` as well, and no scene
/// needs them.
fn check_layout(a: &gltf::Accessor) -> Result<(), String> {
    if a.count() == 0 {
        return Err("count is 0".into());
    }
    if a.sparse().is_some() {
        return Err("sparse accessors are not supported".into());
    }
    let Some(view) = a.view() else {
        return Ok(());
    };
    let size = a.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "bufferViews[{}].byteStride {stride} is shorter than its {size}-byte elements",
            view.index()
        ));
    }
    let end = (a.count() - 1).checked_mul(stride).and_then(|n| n.checked_add(a.offset().checked_add(size)?));
    match end {
        Some(end) if end <= view.length() => Ok(()),
        _ => Err(format!(
            "{} elements of {size} bytes every {stride} from byteOffset {} run past bufferViews[{}] ({} bytes)",
            a.count(),
            a.offset(),
            view.index(),
            view.length()
        )),
    }
}

/// The triangles a primitive's vertex count makes (glTF 2.0 spec 3.7.2.1),
/// before its data is read.
fn declared_triangles(prim: &gltf::Primitive) -> usize {
    let count = prim.indices().or_else(|| prim.get(&gltf::Semantic::Positions)).map_or(0, |a| a.count());
    match prim.mode() {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

/// Triangles of a primitive (glTF 2.0 spec 3.7.2.1): a strip's triangle i
/// is (i, i + 1 + i % 2, i + 2 - i % 2), a fan's is (i + 1, i + 2, 0).
fn triangulate(mode: Mode, list: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::TriangleStrip => {
            (0..list.len().saturating_sub(2)).map(|i| [list[i], list[i + 1 + i % 2], list[i + 2 - i % 2]]).collect()
        }
        Mode::TriangleFan => (0..list.len().saturating_sub(2)).map(|i| [list[i + 1], list[i + 2], list[0]]).collect(),
        _ => list.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    }
}

/// A rough conductor whose normal-incidence reflectance is `f0` at every
/// wavelength (see `gltf_conductor_eta_k`).
fn conductor_from_f0(f0: &Spectrum, alpha: f32) -> Bsdf {
    let eta = Spectrum::from_fn(|l| gltf_conductor_eta_k(f0.eval(l)).0);
    let k = Spectrum::from_fn(|l| gltf_conductor_eta_k(f0.eval(l)).1);
    Bsdf::Conductor(Conductor::new(eta, k, alpha, alpha))
}

/// The complex index (n, k) of a metal with normal-incidence reflectance
/// `r` (clamped to [0, 0.999]).
///
/// Gulbrandsen 2014, "Artist Friendly Metallic Fresnel" (JCGT 3(4)), maps
/// a reflectivity r and an edge tint g to n = g n_min + (1 - g) n_max with
/// n_min = (1 - r) / (1 + r), n_max = (1 + sqrt r) / (1 - sqrt r), and
/// k^2 = ((n + 1)^2 r - (n - 1)^2) / (1 - r), which gives F(0) = r exactly.
/// glTF has no edge tint; g = 1 - (1 - r)^3 is a fit to the Schlick curve
/// glTF viewers draw, F = r + (1 - r)(1 - cos)^5: for r in [0.02, 0.99]
/// the exact Fresnel reflectance of (n, k) stays within 0.055 of it at every
/// angle and within 0.016 in hemispherical albedo (a constant g = 1 is off
/// by up to 0.22 near r = 0.2).
pub fn gltf_conductor_eta_k(r: f32) -> (f32, f32) {
    let r = r.clamp(0.0, 0.999);
    let g = 1.0 - (1.0 - r).powi(3);
    let sr = r.sqrt();
    let n_min = (1.0 - r) / (1.0 + r);
    let n_max = (1.0 + sr) / (1.0 - sr);
    let n = g * n_min + (1.0 - g) * n_max;
    let k2 = ((n + 1.0) * (n + 1.0) * r - (n - 1.0) * (n - 1.0)) / (1.0 - r);
    (n, k2.max(0.0).sqrt())
}

/// The default framing (see DEFAULT_FOV_DEG).
fn default_camera(meshes: &[ImportedMesh]) -> Option<Camera> {
    let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
    for m in meshes {
        for p in m.mesh.triangles().flatten() {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    // In f64: the box's diagonal passes f32 for extents beyond ~1.8e19.
    let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
    let (center, radius) =
        if lo.cmple(hi).all() { ((lo + hi) * 0.5, (hi - lo).length() * 0.5) } else { (DVec3::ZERO, 1.0) };
    let radius = if radius > 0.0 { radius } else { 1.0 };
    let elevation = (DEFAULT_ELEVATION_DEG as f64).to_radians();
    let dir = DVec3::new(0.0, elevation.sin(), elevation.cos());
    let distance = radius / ((DEFAULT_FOV_DEG as f64).to_radians() * 0.5).sin();
    let position = (center + dir * distance).as_vec3a();
    let width = (DEFAULT_HEIGHT as f32 * DEFAULT_ASPECT).round() as u32;
    position
        .is_finite()
        .then(|| Camera::new(position, center.as_vec3a(), Vec3A::Y, DEFAULT_FOV_DEG, width, DEFAULT_HEIGHT))
}

/// Standard or URL-safe base64 (RFC 4648), padding optional; None if
/// malformed.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let s = s.trim_end_matches('=');
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Decodes the %XX escapes of a relative URI.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let hex = |c: u8| (c as char).to_digit(16);
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// What a camera node's world transform does to the image beyond placing
/// the camera, which prism's pinhole (position, view -z, up +y; right =
/// view x up) cannot show: a mirror (glTF 3.10.1 puts the local +x to the
/// right, so a rasteriser's view, the inverse of this transform, flips the
/// image) or a scale that is not the same on every axis (it stretches the
/// image). A uniform scale changes nothing after the perspective divide.
fn camera_distortion(world: &Affine3A) -> Option<&'static str> {
    let m = world.matrix3.as_dmat3();
    if m.determinant() < 0.0 {
        return Some("mirrors (its determinant is negative)");
    }
    let g = m.transpose() * m;
    let s2 = (g.x_axis.x + g.y_axis.y + g.z_axis.z) / 3.0;
    let off = (g - glam::DMat3::from_diagonal(glam::DVec3::splat(s2))).to_cols_array();
    (off.iter().any(|e| e.abs() > 1e-4 * s2)).then_some("scales unevenly or shears")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_decodes_rfc4648_vectors() {
        assert_eq!(base64_decode("").unwrap(), b"");
        assert_eq!(base64_decode("Zg==").unwrap(), b"f");
        assert_eq!(base64_decode("Zm9vYg==").unwrap(), b"foob");
        assert_eq!(base64_decode("Zm9vYmFy").unwrap(), b"foobar");
        assert!(base64_decode("Zm9v*").is_none());
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
    }

    #[test]
    fn strips_and_fans_follow_the_spec() {
        assert_eq!(triangulate(Mode::TriangleStrip, &[0, 1, 2, 3]), vec![[0, 1, 2], [1, 3, 2]]);
        assert_eq!(triangulate(Mode::TriangleFan, &[0, 1, 2, 3]), vec![[1, 2, 0], [2, 3, 0]]);
    }
}
