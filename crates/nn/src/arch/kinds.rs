//! What the networks are for and what their training batches carry: below
//! the training settings (`crate::config`) and the data pipeline
//! (`crate::data`), which use them, so that the networks depend on neither.

use serde::{Deserialize, Serialize};

/// What `pgrf train` trains: the paper's two methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// SPC: the SID U-Net denoiser, L1(denoise(noisy x ratio), clean).
    #[serde(alias = "denoiser")]
    Spc,
    /// PGRF: the SR3 velocity field of the physics-guided rectified flow.
    #[serde(alias = "flow")]
    Pgrf,
}

impl Method {
    /// The name users see ("spc", "pgrf").
    pub fn name(self) -> &'static str {
        match self {
            Method::Spc => "spc",
            Method::Pgrf => "pgrf",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = pgrf_core::parse::ParseError;
    /// `spc` or `pgrf`; `denoiser` and `flow` (what they train) also work.
    fn from_str(s: &str) -> std::result::Result<Method, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "spc" | "denoiser" => Ok(Method::Spc),
            "pgrf" | "flow" => Ok(Method::Pgrf),
            o => Err(pgrf_core::parse::ParseError::unknown_name(
                s,
                format!("unknown method '{o}' (spc or pgrf; denoiser and flow name the same)"),
            )),
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What to put in a batch besides (noisy, clean).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Extras {
    /// Nothing else: the denoiser's batches.
    None,
    /// X0 ~ N(0, I) and t ~ U(0, t_max) per item, for the rectified flow;
    /// `t_max` in (0, 1] (1: Algorithm 1's U(0, 1)).
    Flow {
        /// Upper end of the training times (`pgrf train --time-max`).
        t_max: f32,
    },
}
