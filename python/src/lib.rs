//! `cloudgi._cloudgi`: the native half of the Python package. It takes plain values (scene
//! text or JSON, `.npy` bytes) and gives bytes back; `cloudgi/__init__.py` turns numpy arrays
//! and dicts into those and back, so this crate needs no numpy bindings.

mod scene_input;

use cloudgi::{Density, Error, Image, Options, Progress, VoxelSize};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Mutex;
use std::time::Duration;

create_exception!(cloudgi, CloudgiError, PyException, "Base of every cloudgi error.");
create_exception!(
    cloudgi,
    SceneError,
    CloudgiError,
    "The scene (a file, TOML text, a dict or an argument) is invalid: the message names the field and the fix."
);
create_exception!(
    cloudgi,
    FormatError,
    CloudgiError,
    "A data file or array (grid, image) is malformed, of an unsupported type, or holds bad values."
);
create_exception!(cloudgi, FileError, CloudgiError, "A file could not be read or written.");
create_exception!(
    cloudgi,
    SolverError,
    CloudgiError,
    "A numerical stage failed (e.g. the diffusion solver did not converge)."
);
create_exception!(cloudgi, CancelledError, CloudgiError, "The render was cancelled.");

/// The Python exception of a library error, with the command line's message.
fn to_py(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Invalid { .. } | Error::Parse { .. } => SceneError::new_err(msg),
        Error::Format { .. } => FormatError::new_err(msg),
        Error::Io { .. } => FileError::new_err(msg),
        Error::Numerical { .. } => SolverError::new_err(msg),
        Error::Cancelled => CancelledError::new_err(msg),
    }
}

/// Where the render is, for the calling thread to report: (stage, done, total) and the
/// warnings not yet shown.
#[derive(Default)]
struct Reported {
    stage: Mutex<(String, u64, u64)>,
    warnings: Mutex<Vec<String>>,
}

impl Progress for Reported {
    fn begin(&self, stage: &str, total: u64) {
        if let Ok(mut s) = self.stage.lock() {
            *s = (stage.to_string(), 0, total);
        }
    }
    fn advance(&self, n: u64) {
        if let Ok(mut s) = self.stage.lock() {
            s.1 = (s.1 + n).min(s.2);
        }
    }
    fn end(&self) {
        if let Ok(mut s) = self.stage.lock() {
            s.1 = s.2;
        }
    }
    fn warn(&self, msg: &str) {
        if let Ok(mut w) = self.warnings.lock() {
            w.push(msg.to_string());
        }
    }
}

/// How often the calling thread wakes during a render to report progress and check for Ctrl-C.
const POLL: Duration = Duration::from_millis(50);

/// The image and each AOV as little-endian float32 bytes, (height, width, 3) row-major.
type Layers = Vec<(String, Vec<u8>)>;

/// [`Layers`] as Python byte arrays (writable, for numpy), with the width and height.
type PyImages<'py> = (u32, u32, Vec<(String, Bound<'py, PyByteArray>)>);

fn layer_bytes(px: &[cloudgi::Rgb]) -> Vec<u8> {
    px.iter().flat_map(|p| p.to_array()).flat_map(f32::to_le_bytes).collect()
}

/// `voxel_size` as Python passes it: one edge (m) or `[x, y, z]` (the wrapper has checked which).
#[derive(FromPyObject)]
enum Edges {
    Cube(f32),
    Box([f32; 3]),
}

impl From<Edges> for VoxelSize {
    fn from(e: Edges) -> VoxelSize {
        match e {
            Edges::Cube(h) => VoxelSize::Cube(h),
            Edges::Box(h) => VoxelSize::Box(h),
        }
    }
}

/// Build the scene and render it on a worker thread while this thread, holding the GIL only
/// briefly every [`POLL`], calls `progress(stage, done, total)`, issues warnings and checks for
/// signals (Ctrl-C raises KeyboardInterrupt here, which cancels the render).
#[pyfunction]
#[pyo3(signature = (kind, payload, overrides, keywords, npy=None, voxel_size=None, origin=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    kind: &str,
    payload: &str,
    overrides: &str,
    keywords: Vec<String>,
    npy: Option<&[u8]>,
    voxel_size: Option<Edges>,
    origin: Option<[f32; 3]>,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<PyImages<'py>> {
    let input = scene_input::SceneInput::new(kind, payload, overrides, keywords).map_err(to_py)?;
    let arguments = [
        ("medium.voxel_size", "voxel_size", voxel_size.is_some()),
        ("medium.origin", "origin", origin.is_some()),
    ];
    let cancel = AtomicBool::new(false);
    let reported = Reported::default();
    let (tx, rx) = mpsc::channel();
    let work = || -> cloudgi::Result<(u32, u32, Layers)> {
        let (desc, source, base) = input.desc()?;
        let density = match npy {
            Some(b) => Some(Density::from_npy(
                b,
                voxel_size.map_or(desc.medium.voxel_size, Edges::into),
                origin.unwrap_or(desc.medium.origin),
            )?),
            None => None,
        };
        let scene = cloudgi::Scene::build_with(desc, &source, &base, density).map_err(|e| match e {
            // The density's placement came from render()'s own arguments: name them.
            Error::Invalid { file, field, message } if file == cloudgi::DENSITY_SOURCE => {
                let field = match arguments.iter().find(|(key, _, given)| *given && *key == field) {
                    Some((_, argument, _)) => format!("{argument} (argument)"),
                    None => field,
                };
                Error::Invalid { file, field, message }
            }
            e => input.blame_field(e, &source),
        })?;
        for note in scene.notes() {
            reported.warn(note);
        }
        for w in cloudgi::ignored_settings(&scene, npy.is_some(), &input.given_by(&source)) {
            reported.warn(&w);
        }
        for w in cloudgi::scene_warnings(&scene) {
            reported.warn(&w);
        }
        let options = Options {
            progress: Some(&reported),
            cancel: Some(&cancel),
        };
        let out = cloudgi::render(&scene, scene.desc.render.method, &options)?;
        let mut layers = vec![("rgb".to_string(), layer_bytes(&out.image.pixels))];
        layers.extend(out.aovs.iter().map(|(n, px)| (n.clone(), layer_bytes(px))));
        Ok((out.image.width, out.image.height, layers))
    };
    let mut interrupted: Option<PyErr> = None;
    let mut shown = (String::new(), u64::MAX, 0);
    // A receiver is not Sync; the lock lets the GIL-free wait borrow it.
    let rx = Mutex::new(rx);
    let result = std::thread::scope(|s| {
        s.spawn(|| {
            // Owned here: a panic in the render drops it, so the wait below ends (and the scope
            // raises the panic) instead of waiting for a result that never comes.
            let tx = tx;
            let _ = tx.send(work());
        });
        loop {
            let got = py.detach(|| match rx.lock() {
                Ok(rx) => rx.recv_timeout(POLL),
                Err(_) => Err(mpsc::RecvTimeoutError::Disconnected),
            });
            if interrupted.is_none() {
                if let Err(e) = report(py, &reported, progress.as_ref(), &mut shown) {
                    cancel.store(true, Ordering::Relaxed);
                    interrupted = Some(e);
                }
            }
            match got {
                Ok(r) => break r,
                Err(mpsc::RecvTimeoutError::Disconnected) => break Err(Error::Cancelled),
                Err(mpsc::RecvTimeoutError::Timeout) => {}
            }
        }
    });
    if let Some(e) = interrupted {
        return Err(e);
    }
    let (w, h, layers) = result.map_err(to_py)?;
    let arrays = layers.into_iter().map(|(n, b)| (n, PyByteArray::new(py, &b))).collect();
    Ok((w, h, arrays))
}

/// Issue `msg` as a Python `RuntimeWarning`.
fn runtime_warning(py: Python<'_>, msg: &str) -> PyResult<()> {
    let category = py.get_type::<pyo3::exceptions::PyRuntimeWarning>();
    PyErr::warn(py, category.as_any(), &std::ffi::CString::new(msg).unwrap_or_default(), 1)
}

/// Show the render's progress and warnings and check for signals (on the main thread a pending
/// Ctrl-C raises KeyboardInterrupt here).
fn report(py: Python<'_>, reported: &Reported, progress: Option<&Bound<'_, PyAny>>, shown: &mut (String, u64, u64)) -> PyResult<()> {
    py.check_signals()?;
    let warnings = reported.warnings.lock().map(|mut w| std::mem::take(&mut *w)).unwrap_or_default();
    for w in warnings {
        runtime_warning(py, &w)?;
    }
    let now = reported.stage.lock().map(|s| s.clone()).unwrap_or_default();
    if let Some(cb) = progress {
        if now != *shown && !now.0.is_empty() {
            cb.call1((now.0.as_str(), now.1, now.2))?;
            *shown = now;
        }
    }
    Ok(())
}

/// Write `layers` ("rgb" first, then AOVs; float32 little-endian bytes of (height, width, 3))
/// to an OpenEXR file atomically, as the command line writes a render.
#[pyfunction]
fn write_exr(py: Python<'_>, path: std::path::PathBuf, width: u32, height: u32, layers: Vec<(String, Bound<'_, PyBytes>)>) -> PyResult<()> {
    let n = width as usize * height as usize;
    let mut image = Image::new(width, height);
    for (name, bytes) in layers {
        let bytes = bytes.as_bytes();
        if bytes.len() != n * 12 {
            return Err(FormatError::new_err(format!(
                "{}: layer `{name}` has {} bytes, not {width}×{height}×3 float32 values",
                path.display(),
                bytes.len()
            )));
        }
        let px = bytes
            .chunks_exact(12)
            .map(|c| {
                let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
                cloudgi::Rgb::new(f(0), f(4), f(8))
            })
            .collect();
        if name == "rgb" {
            image.pixels = px;
        } else {
            image.layers.push((name, px));
        }
    }
    py.detach(|| image.write_exr(&path)).map_err(to_py)
}

/// Check, before any work, that `path` can be written as an output file (see
/// `cloudgi::check_output_file`); `source` and `field` name the function and argument it came
/// from. A [`FileError`], whatever the check finds.
#[pyfunction]
fn check_output(path: std::path::PathBuf, source: &str, field: &str) -> PyResult<()> {
    cloudgi::check_output_file(&path, source, field).map_err(|e| FileError::new_err(e.to_string()))
}

/// Read grid `grid` of a grid file (`.vdb`, `.npy`, `.raw`, `.vol`): (nx, ny, nz), float32
/// little-endian bytes indexed [z][y][x], voxel size (m) and origin (m).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn load_grid<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    grid: &str,
) -> PyResult<([usize; 3], Bound<'py, PyByteArray>, [f32; 3], [f32; 3])> {
    let d = py.detach(|| Density::load(&path, grid)).map_err(to_py)?;
    for note in d.notes() {
        runtime_warning(py, note)?;
    }
    let bytes: Vec<u8> = d.values().iter().flat_map(|v| v.to_le_bytes()).collect();
    Ok((d.dims(), PyByteArray::new(py, &bytes), d.voxel_size(), d.origin()))
}

/// Refuse, before numpy copies it, a density of `shape` whose copies (`itemsize` bytes a
/// value) and grid would not fit in the available memory ([`Density::check_fits`]).
#[pyfunction]
fn check_density_fits(shape: Vec<u64>, itemsize: u64) -> PyResult<()> {
    Density::check_fits(&shape, itemsize).map_err(to_py)
}

/// Refuse, before numpy converts them, `layers` images of `width`×`height` whose copies
/// (`itemsize` bytes a value) and EXR would not fit in the available memory ([`Image::check_fits`]).
#[pyfunction]
fn check_image_fits(path: std::path::PathBuf, width: u32, height: u32, layers: u32, itemsize: u64) -> PyResult<()> {
    Image::check_fits(width, height, layers, itemsize, &path.display().to_string(), "images").map_err(to_py)
}

/// The scene a render would use, as TOML (defaults filled in, overrides applied).
#[pyfunction]
fn scene_toml(kind: &str, payload: &str, overrides: &str, keywords: Vec<String>) -> PyResult<String> {
    let input = scene_input::SceneInput::new(kind, payload, overrides, keywords).map_err(to_py)?;
    let (desc, _, _) = input.desc().map_err(to_py)?;
    Ok(desc.to_toml())
}

#[pymodule]
fn _cloudgi(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("CloudgiError", py.get_type::<CloudgiError>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("FormatError", py.get_type::<FormatError>())?;
    m.add("FileError", py.get_type::<FileError>())?;
    m.add("SolverError", py.get_type::<SolverError>())?;
    m.add("CancelledError", py.get_type::<CancelledError>())?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(check_output, m)?)?;
    m.add_function(wrap_pyfunction!(load_grid, m)?)?;
    m.add_function(wrap_pyfunction!(scene_toml, m)?)?;
    m.add_function(wrap_pyfunction!(check_density_fits, m)?)?;
    m.add_function(wrap_pyfunction!(check_image_fits, m)?)?;
    Ok(())
}
