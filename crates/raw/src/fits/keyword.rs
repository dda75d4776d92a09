//! Header values read as the type pgrf needs (a number, an integer, a
//! string, a binning factor, a row order), each refusal naming its keyword:
//! a caller ([`crate::RawError::FitsKeyword`]) can tell which card of the
//! file to fix or override.

use super::RowOrder;
use fitsrs::card::Value;
use fitsrs::hdu::header::ValueMap;

/// A header card whose value pgrf cannot use; each variant names the
/// keyword (`key`) and shows the value as the file wrote it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum KeywordError {
    /// A value that is not a number where a number belongs (EXPTIME,
    /// CCD-TEMP, BZERO, ...).
    #[error("{key} = {value} is not a number")]
    NotANumber {
        /// The keyword.
        key: String,
        /// The value as written (a string quoted).
        value: String,
    },
    /// A number that is infinite or not a number.
    #[error("{key} = {value} is not a finite number")]
    NotFinite {
        /// The keyword.
        key: String,
        /// The value.
        value: f64,
    },
    /// A number with a fraction (or beyond 9e15) where an integer belongs
    /// (BLANK, ISOSPEED, XBAYROFF, ...).
    #[error("{key} = {value} is not an integer")]
    NotAnInteger {
        /// The keyword.
        key: String,
        /// The value.
        value: f64,
    },
    /// A value that is not a string where text belongs (INSTRUME,
    /// DATE-OBS, ROWORDER).
    #[error("{key} = {value} is not a string")]
    NotAString {
        /// The keyword.
        key: String,
        /// The value as written.
        value: String,
    },
    /// XBINNING or YBINNING outside 1 to 64.
    #[error("{key} = {value} is not a binning factor (1 to 64)")]
    Binning {
        /// The keyword.
        key: String,
        /// The value.
        value: i64,
    },
    /// A ROWORDER that is neither TOP-DOWN nor BOTTOM-UP.
    #[error("ROWORDER = '{value}' is neither TOP-DOWN nor BOTTOM-UP")]
    RowOrder {
        /// The value, upper-cased.
        value: String,
    },
    /// BSCALE = 0, which would make every sample BZERO.
    #[error("BSCALE = 0: every sample would read as BZERO")]
    ZeroScale,
}

impl KeywordError {
    /// The keyword at fault.
    pub fn key(&self) -> &str {
        match self {
            KeywordError::NotANumber { key, .. }
            | KeywordError::NotFinite { key, .. }
            | KeywordError::NotAnInteger { key, .. }
            | KeywordError::NotAString { key, .. }
            | KeywordError::Binning { key, .. } => key,
            KeywordError::RowOrder { .. } => "ROWORDER",
            KeywordError::ZeroScale => "BSCALE",
        }
    }
}

type Result<T> = std::result::Result<T, KeywordError>;

/// A numeric keyword (integer, real, or a string holding a number).
pub(super) fn number(header: &ValueMap, key: &str) -> Result<Option<f64>> {
    let v = match header.get(key) {
        None | Some(Value::Undefined) => return Ok(None),
        Some(Value::Integer { value, .. }) => *value as f64,
        Some(Value::Float { value, .. }) => *value,
        Some(Value::String { value, .. }) => {
            let t = value.trim();
            if t.is_empty() {
                return Ok(None);
            }
            t.parse::<f64>().map_err(|_| KeywordError::NotANumber {
                key: key.to_string(),
                value: format!("'{t}'"),
            })?
        }
        Some(other) => {
            return Err(KeywordError::NotANumber {
                key: key.to_string(),
                value: show(other),
            })
        }
    };
    if !v.is_finite() {
        return Err(KeywordError::NotFinite {
            key: key.to_string(),
            value: v,
        });
    }
    Ok(Some(v))
}

/// An integer keyword (a real with no fraction is accepted).
pub(super) fn integer(header: &ValueMap, key: &str) -> Result<Option<i64>> {
    match header.get(key) {
        Some(Value::Integer { value, .. }) => Ok(Some(*value)),
        _ => match number(header, key)? {
            None => Ok(None),
            Some(v) if v.fract() == 0.0 && v.abs() < 9e15 => Ok(Some(v as i64)),
            Some(v) => Err(KeywordError::NotAnInteger {
                key: key.to_string(),
                value: v,
            }),
        },
    }
}

/// A string keyword, trimmed; blank reads as absent.
pub(super) fn string(header: &ValueMap, key: &str) -> Result<Option<String>> {
    match header.get(key) {
        None | Some(Value::Undefined) => Ok(None),
        Some(Value::String { value, .. }) => {
            let t = value.trim();
            Ok((!t.is_empty()).then(|| t.to_string()))
        }
        Some(other) => Err(KeywordError::NotAString {
            key: key.to_string(),
            value: show(other),
        }),
    }
}

/// A descriptive keyword (IMAGETYP, FILTER, OBJECT) as text: a string
/// trimmed, any other value as written (a driver that writes FILTER = 2
/// names its filter wheel's slot); None when absent or empty. Never an
/// error: what only describes a frame does not make it unreadable.
pub(super) fn text(header: &ValueMap, key: &str) -> Option<String> {
    match header.get(key) {
        None | Some(Value::Undefined) => None,
        Some(Value::String { value, .. }) => {
            let t = value.trim();
            (!t.is_empty()).then(|| t.to_string())
        }
        Some(other) => Some(show(other)),
    }
}

/// XBINNING and YBINNING (1 to 64 each; an absent one is 1), None when
/// the header states neither.
pub(super) fn binning(header: &ValueMap) -> Result<Option<(u32, u32)>> {
    let axis = |key: &str| -> Result<Option<u32>> {
        match integer(header, key)? {
            None => Ok(None),
            Some(v) if (1..=64).contains(&v) => Ok(Some(v as u32)),
            Some(v) => Err(KeywordError::Binning {
                key: key.to_string(),
                value: v,
            }),
        }
    };
    Ok(match (axis("XBINNING")?, axis("YBINNING")?) {
        (None, None) => None,
        (x, y) => Some((x.unwrap_or(1), y.unwrap_or(1))),
    })
}

/// ROWORDER: TOP-DOWN or BOTTOM-UP (any case), `None` when absent; any
/// other value is refused, since what pgrf writes from the frame states it.
pub(super) fn row_order(header: &ValueMap) -> Result<Option<RowOrder>> {
    match string(header, "ROWORDER")? {
        None => Ok(None),
        Some(r) => match r.to_ascii_uppercase().as_str() {
            "TOP-DOWN" => Ok(Some(RowOrder::TopDown)),
            "BOTTOM-UP" => Ok(Some(RowOrder::BottomUp)),
            other => Err(KeywordError::RowOrder {
                value: other.to_string(),
            }),
        },
    }
}

/// A header value as the file wrote it, for messages.
pub(super) fn show(v: &Value) -> String {
    match v {
        Value::Integer { value, .. } => value.to_string(),
        Value::Float { value, .. } => value.to_string(),
        Value::Logical { value, .. } => if *value { "T" } else { "F" }.to_string(),
        Value::String { value, .. } => format!("'{value}'"),
        Value::Undefined => "(blank)".to_string(),
        Value::Invalid(s) => format!("'{}'", s.trim()),
    }
}
