//! Which physical noise sources a synthesis includes, named as in the paper's
//! ablation tables.

use crate::error::{NoiseError, Result};
use std::fmt;

/// P photon shot, G source-follower (read), H row, Q quantisation,
/// F fixed pattern, A dark-current shot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Components {
    pub(crate) photon: bool,
    pub(crate) read: bool,
    pub(crate) row: bool,
    pub(crate) quant: bool,
    pub(crate) fixed_pattern: bool,
    pub(crate) dark: bool,
}

impl Components {
    /// Every term: the full PGRF model ("P,G,H,Q,F,A").
    pub const ALL: Components = Components {
        photon: true,
        read: true,
        row: true,
        quant: true,
        fixed_pattern: true,
        dark: true,
    };
    /// The Poisson-Gaussian model's terms: "P,G".
    pub const PG: Components = Components {
        photon: true,
        read: true,
        ..Components::NONE
    };
    /// ELD's model's terms: "P,G,H,Q,F" (its per-channel colour bias is
    /// the fixed pattern F).
    pub const ELD: Components = Components {
        dark: false,
        ..Components::ALL
    };
    /// Whether row noise (H) is drawn.
    pub fn row(&self) -> bool {
        self.row
    }
    pub(crate) const NONE: Components = Components {
        photon: false,
        read: false,
        row: false,
        quant: false,
        fixed_pattern: false,
        dark: false,
    };

    /// Parse "P,G,H,Q,F,A", "PGHQ", "all" or "none".
    pub fn parse(s: &str) -> Result<Components> {
        match s.trim().to_ascii_lowercase().as_str() {
            "all" => return Ok(Self::ALL),
            "none" => return Ok(Self::NONE),
            _ => {}
        }
        let mut c = Self::NONE;
        for ch in s.chars().filter(|c| !matches!(c, ',' | ' ' | '+')) {
            let flag = match ch {
                'P' => &mut c.photon,
                'G' => &mut c.read,
                'H' => &mut c.row,
                'Q' => &mut c.quant,
                'F' => &mut c.fixed_pattern,
                'A' => &mut c.dark,
                o => {
                    return Err(NoiseError::UnknownComponent {
                        component: o,
                        list: s.into(),
                    })
                }
            };
            *flag = true;
        }
        Ok(c)
    }
}

impl fmt::Display for Components {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<&str> = [
            (self.photon, "P"),
            (self.read, "G"),
            (self.row, "H"),
            (self.quant, "Q"),
            (self.fixed_pattern, "F"),
            (self.dark, "A"),
        ]
        .into_iter()
        .filter_map(|(on, n)| on.then_some(n))
        .collect();
        f.write_str(&names.join(","))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_print() {
        assert_eq!(Components::parse("P,G,H,Q,F,A").unwrap(), Components::ALL);
        assert_eq!(Components::parse("PG").unwrap().to_string(), "P,G");
        assert_eq!(Components::PG, Components::parse("P,G").unwrap());
        assert_eq!(Components::ELD, Components::parse("P,G,H,Q,F").unwrap());
        assert_eq!(Components::parse("all").unwrap(), Components::ALL);
        assert!(Components::parse("P,X").is_err());
        assert!(Components::parse("p").is_err());
    }
}
