//! Learning-rate schedules. The default is ELD's recipe: 1e-4 for the first
//! half of training, 5e-5 until 90 %, then 1e-5 (ELD trains 200 epochs and
//! steps down after epochs 100 and 180); expressed in fractions of the run so
//! that it scales to any number of steps.

use serde::{Deserialize, Serialize};

/// How the learning rate changes over a run of `total` steps (`--schedule
/// eld|constant|cosine`, the same names in TOML).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Schedule {
    /// lr, lr/2 after 50 % of the steps, lr/10 after 90 %.
    Eld,
    /// lr throughout.
    Constant,
    /// Half-cosine from lr to 0.
    Cosine,
}

impl std::str::FromStr for Schedule {
    type Err = pgrf_core::parse::ParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "eld" => Ok(Self::Eld),
            "constant" => Ok(Self::Constant),
            "cosine" => Ok(Self::Cosine),
            _ => Err(pgrf_core::parse::ParseError::unknown_name(
                s,
                format!("unknown schedule '{s}' (expected eld, constant or cosine)"),
            )),
        }
    }
}

impl std::fmt::Display for Schedule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Schedule::Eld => "eld",
            Schedule::Constant => "constant",
            Schedule::Cosine => "cosine",
        })
    }
}

impl Schedule {
    /// Learning rate at `step` (0-based) of `total`, for base rate `lr`.
    pub(crate) fn lr(self, lr: f64, step: u64, total: u64) -> f64 {
        let f = step as f64 / total.max(1) as f64;
        match self {
            Schedule::Constant => lr,
            Schedule::Eld => {
                if f < 0.5 {
                    lr
                } else if f < 0.9 {
                    lr * 0.5
                } else {
                    lr * 0.1
                }
            }
            Schedule::Cosine => lr * 0.5 * (1.0 + (std::f64::consts::PI * f).cos()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eld_steps_at_half_and_ninety_percent() {
        let s = Schedule::Eld;
        assert_eq!(s.lr(1e-4, 0, 200), 1e-4);
        assert_eq!(s.lr(1e-4, 99, 200), 1e-4);
        assert_eq!(s.lr(1e-4, 100, 200), 5e-5);
        assert_eq!(s.lr(1e-4, 179, 200), 5e-5);
        assert!((s.lr(1e-4, 180, 200) - 1e-5).abs() < 1e-18);
        assert!((Schedule::Cosine.lr(1.0, 50, 100) - 0.5).abs() < 1e-12);
        assert_eq!(Schedule::Constant.lr(3.0, 99, 100), 3.0);
        assert!("warmup".parse::<Schedule>().is_err());
    }
}
