//! What an evaluation measures: a method under test, from a packed,
//! normalised and amplified input to its restoration. This crate sits below
//! the network crate, so it cannot name the models; pgrf-nn implements
//! [`MethodUnderTest`] for its restorers, and restorations made outside pgrf
//! are read back from `.npy` files ([`SavedOutputs`]).

use crate::npy::NpyError;
use ndarray::{Array3, ArrayView3};
use std::path::{Path, PathBuf};

/// What a method is told about the case it restores.
#[derive(Clone, Copy, Debug)]
pub struct CaseInfo<'a> {
    /// The case's file-name-safe key (what its `--dump` files are named
    /// after, [`crate::dataset::run::case_key`]).
    pub key: &'a str,
    /// The exposure ratio the input was amplified by.
    pub ratio: f32,
    /// The noise of the capture before amplification, as a noise-aware
    /// method is told it: the synthetic protocol's simulated camera is
    /// calibrated (its true parameters); a file's are what
    /// `pgrf_noise::lookup::find_noise` finds for it.
    pub noise: Option<&'a CaseNoise>,
}

/// A case's noise in DN on its files' scale, and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct CaseNoise {
    /// K, DN per electron.
    pub k: f64,
    /// Read noise, DN.
    pub read: f64,
    /// Row noise, DN.
    pub row: f64,
    /// white - black, DN: the scale of the three.
    pub range: f64,
    /// Where the numbers came from, in words.
    pub source: String,
}

/// A method under evaluation: one column of the table.
pub trait MethodUnderTest {
    /// Its column name in tables, CSV and the worst-images picture.
    fn name(&self) -> &str;

    /// The restoration of `input` (packed `(4, h, w)` R, G1, B, G2,
    /// normalised, multiplied by `case.ratio` and clipped at 1, values below
    /// black kept: a network that reads them clamped clamps them itself), of the
    /// same shape, or why not.
    fn restore(
        &self,
        input: ArrayView3<f32>,
        case: &CaseInfo<'_>,
    ) -> Result<Array3<f32>, RestoreError>;
}

/// Why a method gave no restoration of a case: its saved output could not
/// be read or has another shape than the input, or the method itself
/// failed (a network's error, kept whole for callers that look into it).
#[derive(Debug, thiserror::Error)]
pub enum RestoreError {
    /// A saved output ([`SavedOutputs`]) that could not be read.
    #[error(transparent)]
    Output(#[from] NpyError),
    /// A saved output of another shape than the input.
    #[error("{}: shape {found:?}, the input is {input:?}", path.display())]
    OutputShape {
        /// The output's file.
        path: PathBuf,
        /// Its shape.
        found: (usize, usize, usize),
        /// The input's shape.
        input: (usize, usize, usize),
    },
    /// The method's own error.
    #[error(transparent)]
    Method(Box<dyn std::error::Error + Send + Sync>),
}

impl RestoreError {
    /// The method's own error `e` (a network's, or a message).
    pub fn method(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        RestoreError::Method(e.into())
    }
}

/// A closure as a method: for methods computed in place (and tests).
pub struct FnMethod<F> {
    /// The column name.
    pub name: String,
    /// The restoration.
    pub f: F,
}

impl<F> MethodUnderTest for FnMethod<F>
where
    F: Fn(ArrayView3<f32>, &CaseInfo<'_>) -> Result<Array3<f32>, RestoreError>,
{
    fn name(&self) -> &str {
        &self.name
    }

    fn restore(
        &self,
        input: ArrayView3<f32>,
        case: &CaseInfo<'_>,
    ) -> Result<Array3<f32>, RestoreError> {
        (self.f)(input, case)
    }
}

/// Restorations made outside pgrf (`pgrf eval --outputs NAME=DIR`): case
/// `KEY` is read from `DIR/KEY.output.npy`, packed `(4, H, W)` float32 or
/// float64 of the input's shape.
pub struct SavedOutputs {
    name: String,
    dir: PathBuf,
}

impl SavedOutputs {
    /// The column `name`, read from folder `dir`.
    pub fn new(name: impl Into<String>, dir: impl Into<PathBuf>) -> SavedOutputs {
        SavedOutputs {
            name: name.into(),
            dir: dir.into(),
        }
    }
}

impl MethodUnderTest for SavedOutputs {
    fn name(&self) -> &str {
        &self.name
    }

    fn restore(
        &self,
        input: ArrayView3<f32>,
        case: &CaseInfo<'_>,
    ) -> Result<Array3<f32>, RestoreError> {
        read_output(&self.dir, case.key, input)
    }
}

/// The outside method's restoration of case `key`: DIR/KEY.output.npy, of
/// the input's shape (a larger file is refused before it is read).
fn read_output(dir: &Path, key: &str, input: ArrayView3<f32>) -> Result<Array3<f32>, RestoreError> {
    let path = dir.join(format!("{key}.output.npy"));
    let out = crate::npy::read(&path, 8 * input.len() as u64 + 65_536)?;
    if out.dim() != input.dim() {
        return Err(RestoreError::OutputShape {
            path,
            found: out.dim(),
            input: input.dim(),
        });
    }
    Ok(out)
}
