//! RAW frames in and out: `read` gives the packed normalised planes and the
//! frame's metadata (a dict the Python side turns into `pgrf.Metadata`),
//! `write_dng` turns packed planes and metadata back into a DNG. The
//! metadata carries an opaque [`Header`] (the decoded frame without its
//! pixels) so that a DNG written from a frame pgrf read keeps everything the
//! file had (EXIF, colour matrices, FITS cards), as `pgrf synth` keeps it.

use crate::errors::{bad, to_py};
use crate::threads::run;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray3};
use pgrf_core::parse::ParseError;
use pgrf_raw::{pack_normalized, unpack_normalized, Cfa, ColorMatrix, RawFrame};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

/// The decoded frame a `pgrf.Metadata` came from, without its pixels:
/// opaque, kept so that writing keeps what the file had.
#[pyclass(frozen, module = "pgrf._pgrf")]
pub struct Header {
    pub(crate) frame: RawFrame,
}

#[pymethods]
impl Header {
    fn __repr__(&self) -> String {
        let f = &self.frame;
        format!(
            "<pgrf header {} {} {}x{}>",
            f.make, f.model, f.width, f.height
        )
    }
}

/// The metadata of `frame` as the dict `pgrf.Metadata` is built from; the
/// frame itself, its pixels dropped, becomes the dict's header (taken by
/// value: no copy of a full mosaic only to drop it).
pub fn meta_dict<'py>(py: Python<'py>, mut frame: RawFrame) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("width", frame.width)?;
    d.set_item("height", frame.height)?;
    d.set_item("cfa", if frame.mono { "mono" } else { frame.cfa.name() })?;
    d.set_item("black", frame.black.to_vec())?;
    d.set_item("white", frame.white)?;
    d.set_item("bits", frame.bits)?;
    d.set_item("wb", frame.wb.map(|w| w.to_vec()))?;
    let matrices = PyList::empty(py);
    for m in &frame.color_matrices {
        let rows: Vec<Vec<f32>> = m.xyz_to_cam.iter().map(|r| r.to_vec()).collect();
        matrices.append((m.illuminant.clone(), rows))?;
    }
    d.set_item("color_matrices", matrices)?;
    d.set_item("iso", frame.iso)?;
    d.set_item("exposure_s", frame.exposure_s)?;
    d.set_item("make", frame.make.clone())?;
    d.set_item("model", frame.model.clone())?;
    d.set_item("orientation", frame.orientation)?;
    d.set_item("temperature_c", frame.temperature_c)?;
    d.set_item(
        "noise_profile",
        frame
            .noise_profile
            .as_ref()
            .map(|v| v.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>()),
    )?;
    frame.mosaic = Vec::new();
    d.set_item("header", Header { frame })?;
    Ok(d)
}

/// Field `key` of the metadata dict, converted; refused with the field's name.
fn item<'py, T: pyo3::conversion::FromPyObjectOwned<'py>>(
    d: &Bound<'py, PyDict>,
    key: &str,
) -> PyResult<T> {
    match d.get_item(key)? {
        Some(v) => v.extract::<T>().map_err(|e| {
            let e: PyErr = e.into();
            bad(format!("metadata field {key}: {e}"))
        }),
        None => Err(bad(format!("metadata has no field {key}"))),
    }
}

/// The frame described by metadata `d` (a `pgrf.Metadata`'s fields), with
/// no pixels (an empty mosaic: no size a caller states is allocated before
/// it is checked against an array it holds, see [`with_pixels`]): the
/// header's frame when there is one (its layout must be
/// the one `d` states), else one built from the fields; the descriptive
/// fields (ISO, exposure, camera, white balance, matrices, orientation,
/// temperature, NoiseProfile) are `d`'s.
pub fn frame_of_meta(d: &Bound<'_, PyDict>) -> PyResult<RawFrame> {
    let width: usize = item(d, "width")?;
    let height: usize = item(d, "height")?;
    let cfa_name: String = item(d, "cfa")?;
    let black: [f32; 4] = item(d, "black")?;
    let white: u32 = item(d, "white")?;
    let bits: u32 = item(d, "bits")?;
    let mono = cfa_name.eq_ignore_ascii_case("mono");
    if width < 2 || height < 2 || width > 1 << 16 || height > 1 << 16 {
        return Err(bad(format!(
            "metadata: {width}x{height} is not a frame size pgrf writes (2 to 65536 per side)"
        )));
    }
    let cfa: Cfa = if mono {
        Cfa::Rggb
    } else {
        cfa_name
            .parse()
            .map_err(|e: ParseError| bad(format!("metadata cfa: {e}")))?
    };
    let header = d
        .get_item("header")?
        .filter(|h| !h.is_none())
        .map(|h| {
            h.cast::<Header>()
                .map(|h| h.get().frame.clone())
                .map_err(|_| bad("metadata header: not a pgrf header (leave it None)"))
        })
        .transpose()?;
    let mut frame = match header {
        Some(mut f) => {
            let same = (f.width, f.height, f.cfa, f.mono, f.black, f.white, f.bits)
                == (width, height, cfa, mono, black, white, bits);
            if !same {
                return Err(bad(format!(
                    "metadata: size, cfa, black, white or bits differ from the file's ({}x{} {} black {:?} white {} bits {}); set header=None to describe another frame",
                    f.width,
                    f.height,
                    if f.mono { "mono" } else { f.cfa.name() },
                    f.black,
                    f.white,
                    f.bits
                )));
            }
            f.mosaic = Vec::new();
            f
        }
        None => {
            // Levels and layout checked on a 2 x 2 frame, then given the
            // stated size: the pixels are the caller's to add.
            let mut f = if mono {
                RawFrame::from_mono(2, 2, vec![0; 4], black[0], white)
            } else {
                RawFrame::from_mosaic(2, 2, vec![0; 4], cfa, black, white)
            }
            .map_err(to_py)?;
            (f.width, f.height, f.mosaic) = (width, height, Vec::new());
            f.sensor_size = (height, width);
            f.black = black;
            if !(1..=16).contains(&bits) || (white as u64) >= 1 << bits {
                return Err(bad(format!(
                    "metadata: white {white} does not fit {bits} bits"
                )));
            }
            f.bits = bits;
            f
        }
    };
    describe_from(&mut frame, d)?;
    Ok(frame)
}

/// Set `frame`'s descriptive fields (white balance, matrices, ISO,
/// exposure, camera, orientation, temperature, NoiseProfile) from `d`.
fn describe_from(frame: &mut RawFrame, d: &Bound<'_, PyDict>) -> PyResult<()> {
    frame.wb = item::<Option<[f32; 3]>>(d, "wb")?;
    let matrices: Vec<(String, [[f32; 3]; 3])> = item(d, "color_matrices")?;
    frame.color_matrices = matrices
        .into_iter()
        .map(|(illuminant, xyz_to_cam)| ColorMatrix {
            xyz_to_cam,
            illuminant,
        })
        .collect();
    frame.iso = item(d, "iso")?;
    frame.exposure_s = item(d, "exposure_s")?;
    frame.make = item(d, "make")?;
    frame.model = item(d, "model")?;
    frame.orientation = item(d, "orientation")?;
    frame.temperature_c = item(d, "temperature_c")?;
    frame.noise_profile = item::<Option<Vec<(f64, f64)>>>(d, "noise_profile")?
        .map(|v| v.into_iter().map(|(s, o)| [s, o]).collect());
    Ok(())
}

/// Refuse an array `packed` that is not `frame`'s packed shape `(4, H/2, W/2)`.
pub fn check_packed(frame: &RawFrame, packed: &[usize], what: &str) -> PyResult<()> {
    let (ph, pw) = frame.packed_dims();
    if packed != [4, ph, pw] {
        return Err(bad(format!(
            "{what}: shape {packed:?}, the frame the metadata describes ({}x{}) packs to (4, {ph}, {pw})",
            frame.width, frame.height
        )));
    }
    Ok(())
}

/// `frame` (from [`frame_of_meta`]) with a zero mosaic, once `packed` is
/// known to be its packed shape ([`check_packed`]).
pub fn with_pixels(mut frame: RawFrame, packed: &[usize], what: &str) -> PyResult<RawFrame> {
    check_packed(&frame, packed, what)?;
    frame.mosaic = vec![0; frame.width * frame.height];
    Ok(frame)
}

/// read(path, clip=True) -> (ndarray, dict)
///
/// Decode a RAW file (any camera rawler reads, DNG, FITS): the packed
/// planes `(4, H/2, W/2)` float32 R, G1, B, G2 normalised as
/// (DN - black) / (white - black) (clipped to [0, 1] with `clip`), and the
/// metadata fields.
#[pyfunction]
#[pyo3(signature = (path, clip=true))]
pub fn read<'py>(
    py: Python<'py>,
    path: PathBuf,
    clip: bool,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyDict>)> {
    let (packed, frame) = run(py, || {
        let frame = pgrf_raw::decode_file(&path, &pgrf_raw::LevelOverrides::default())?;
        let packed = pack_normalized(&frame, clip)?;
        Ok::<_, pgrf_raw::RawError>((packed, frame))
    })?;
    let meta = meta_dict(py, frame)?;
    Ok((packed.into_pyarray(py), meta))
}

/// write_dng(path, packed, meta) -> None
///
/// Write packed normalised planes as a DNG of the frame `meta` describes
/// (values rounded to whole DN, clipped to the 16-bit range). Written to a
/// temporary file and renamed, so a failed write leaves no partial file.
#[pyfunction]
pub fn write_dng(
    py: Python<'_>,
    path: PathBuf,
    packed: PyReadonlyArray3<'_, f32>,
    meta: &Bound<'_, PyDict>,
) -> PyResult<()> {
    let view = packed.as_array();
    let template = with_pixels(frame_of_meta(meta)?, view.shape(), "write_dng packed")?;
    run(py, || {
        let frame = unpack_normalized(view, &template)?;
        pgrf_raw::write_dng(&frame, &path, &pgrf_raw::DngOptions::default())
    })
}

/// read_photo(path) -> ndarray
///
/// An ordinary photo (JPEG, PNG, TIFF) as float32 `(H, W, 3)` sRGB-encoded
/// values in [0, 1], for `unprocess`.
#[pyfunction]
pub fn read_photo<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let photo = run(py, || pgrf_scenes::photo::read_photo(&path))?;
    let arr = ndarray::Array3::from_shape_vec((photo.height, photo.width, 3), photo.rgb)
        .map_err(to_py)?;
    Ok(arr.into_pyarray(py))
}
