//! The four phases of a 2x2 Bayer colour filter array.
//!
//! Everything downstream of decode works on planes in the order R, G1, B, G2
//! (the ELD/SID convention), so the CFA's only job is to say where in the 2x2
//! cell each of those four planes sits. G1 is the green on the red row, G2 the
//! green on the blue row.

use pgrf_core::parse::ParseError;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Plane indices in packed order.
pub(crate) const R: usize = 0;
// G1 and G2 complete the set; only the unit tests name them.
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) const G1: usize = 1;
pub(crate) const B: usize = 2;
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) const G2: usize = 3;
/// Names of the packed planes, for reports.
pub const PLANE_NAMES: [&str; 4] = ["R", "G1", "B", "G2"];
/// Names of the packed planes of a monochrome frame: the (row, column)
/// parity of the 2x2 sub-lattice each holds, in packed order.
pub const MONO_PLANE_NAMES: [&str; 4] = ["(0,0)", "(0,1)", "(1,1)", "(1,0)"];

/// A Bayer phase, named by the colours of the top-left 2x2 cell read row by row.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Cfa {
    /// R G / G B: red at (0, 0), blue at (1, 1).
    Rggb,
    /// B G / G R: blue at (0, 0), red at (1, 1).
    Bggr,
    /// G R / B G: red at (0, 1), blue at (1, 0).
    Grbg,
    /// G B / R G: blue at (0, 1), red at (1, 0).
    Gbrg,
}

impl Cfa {
    /// Every Bayer phase, for tests and for trying each phase in turn.
    pub const ALL: [Cfa; 4] = [Cfa::Rggb, Cfa::Bggr, Cfa::Grbg, Cfa::Gbrg];

    /// (row, col) inside the 2x2 cell of the planes R, G1, B, G2.
    pub fn offsets(self) -> [(usize, usize); 4] {
        match self {
            Cfa::Rggb => [(0, 0), (0, 1), (1, 1), (1, 0)],
            Cfa::Bggr => [(1, 1), (1, 0), (0, 0), (0, 1)],
            Cfa::Grbg => [(0, 1), (0, 0), (1, 0), (1, 1)],
            Cfa::Gbrg => [(1, 0), (1, 1), (0, 1), (0, 0)],
        }
    }

    /// Packed plane (R=0, G1=1, B=2, G2=3) of the pixel at (row, col).
    pub fn plane_at(self, row: usize, col: usize) -> usize {
        let cell = (row & 1, col & 1);
        let off = self.offsets();
        (0..4)
            .find(|&p| off[p] == cell)
            .expect("2x2 cell covers all positions")
    }

    /// Colour (0 red, 1 green, 2 blue) of the pixel at (row, col).
    pub fn color_at(self, row: usize, col: usize) -> usize {
        match self.plane_at(row, col) {
            R => 0,
            B => 2,
            _ => 1,
        }
    }

    /// The phase seen by an image that starts `dy` rows and `dx` columns into
    /// this one (what a crop with odd offsets does to the pattern).
    pub(crate) fn shifted(self, dy: usize, dx: usize) -> Cfa {
        let name: String = (0..2)
            .flat_map(|r| (0..2).map(move |c| (r, c)))
            .map(|(r, c)| ['R', 'G', 'B'][self.color_at(r + dy, c + dx)])
            .collect();
        name.parse().expect("a shifted Bayer cell is a Bayer cell")
    }

    /// The four-letter upper-case name ("RGGB", ...), as DNG's CFAPattern,
    /// the CLI and calibration records spell it; [`FromStr`] parses it back.
    pub fn name(self) -> &'static str {
        match self {
            Cfa::Rggb => "RGGB",
            Cfa::Bggr => "BGGR",
            Cfa::Grbg => "GRBG",
            Cfa::Gbrg => "GBRG",
        }
    }
}

impl fmt::Display for Cfa {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Cfa {
    type Err = ParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_uppercase().as_str() {
            "RGGB" => Ok(Cfa::Rggb),
            "BGGR" => Ok(Cfa::Bggr),
            "GRBG" => Ok(Cfa::Grbg),
            "GBRG" => Ok(Cfa::Gbrg),
            other => Err(ParseError::unknown_name(
                s,
                format!(
                    "CFA pattern '{other}' is not a 2x2 Bayer phase (expected RGGB, BGGR, GRBG or GBRG)"
                ),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_agree_with_names() {
        for cfa in Cfa::ALL {
            let name = cfa.name().as_bytes();
            let off = cfa.offsets();
            assert_eq!(name[off[R].0 * 2 + off[R].1], b'R');
            assert_eq!(name[off[B].0 * 2 + off[B].1], b'B');
            // G1 shares a row with R, G2 with B.
            assert_eq!(off[G1].0, off[R].0);
            assert_eq!(off[G2].0, off[B].0);
            assert_eq!(name[off[G1].0 * 2 + off[G1].1], b'G');
            assert_eq!(name[off[G2].0 * 2 + off[G2].1], b'G');
        }
    }

    #[test]
    fn shifts_walk_the_four_phases() {
        assert_eq!(Cfa::Rggb.shifted(0, 1), Cfa::Grbg);
        assert_eq!(Cfa::Rggb.shifted(1, 0), Cfa::Gbrg);
        assert_eq!(Cfa::Rggb.shifted(1, 1), Cfa::Bggr);
        assert_eq!(Cfa::Rggb.shifted(2, 4), Cfa::Rggb);
        for cfa in Cfa::ALL {
            assert_eq!(cfa.shifted(1, 1).shifted(1, 1), cfa);
        }
    }

    #[test]
    fn parse_rejects_non_bayer() {
        assert!("XTRANS".parse::<Cfa>().is_err());
        assert!("RGBG".parse::<Cfa>().is_err());
        assert_eq!("bggr".parse::<Cfa>().unwrap(), Cfa::Bggr);
    }
}
