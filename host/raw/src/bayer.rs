//! Bayer CFA phases.
//!
//! A phase names the colours of a 2x2 quad in reading order (top-left, top-right, bottom-left,
//! bottom-right): `Rggb` has red at `(0, 0)`, green at `(1, 0)` and `(0, 1)`, blue at `(1, 1)`
//! (`(x, y)`, x to the right, y down). Shifting the origin by one photosite in x or y gives
//! another phase ([`BayerPhase::shifted`]).

use std::fmt;

/// A photosite's colour filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CfaColour {
    /// Red.
    Red,
    /// Green.
    Green,
    /// Blue.
    Blue,
}

impl CfaColour {
    /// The DNG / TIFF-EP `CFAPattern` code (0 = red, 1 = green, 2 = blue).
    pub const fn dng_code(self) -> u8 {
        match self {
            Self::Red => 0,
            Self::Green => 1,
            Self::Blue => 2,
        }
    }
}

/// The four 2x2 Bayer phases.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BayerPhase {
    /// R G / G B.
    Rggb,
    /// B G / G R.
    Bggr,
    /// G R / B G.
    Grbg,
    /// G B / R G.
    Gbrg,
}

impl BayerPhase {
    /// Every phase.
    pub const ALL: [Self; 4] = [Self::Rggb, Self::Bggr, Self::Grbg, Self::Gbrg];

    /// The quad's colours in reading order (top-left, top-right, bottom-left, bottom-right).
    pub const fn quad(self) -> [CfaColour; 4] {
        use CfaColour::{Blue as B, Green as G, Red as R};
        match self {
            Self::Rggb => [R, G, G, B],
            Self::Bggr => [B, G, G, R],
            Self::Grbg => [G, R, B, G],
            Self::Gbrg => [G, B, R, G],
        }
    }

    /// The colour of photosite `(x, y)` relative to the phase's origin.
    pub const fn colour_at(self, x: usize, y: usize) -> CfaColour {
        self.quad()[(y % 2) * 2 + (x % 2)]
    }

    /// The phase seen from an origin moved by `(dx, dy)` photosites.
    pub const fn shifted(self, dx: usize, dy: usize) -> Self {
        let q = self.quad();
        let (dx, dy) = (dx % 2, dy % 2);
        let shifted = [
            q[dy * 2 + dx],
            q[dy * 2 + (1 - dx)],
            q[(1 - dy) * 2 + dx],
            q[(1 - dy) * 2 + (1 - dx)],
        ];
        match Self::from_quad(shifted) {
            Some(p) => p,
            // Shifting a Bayer quad always gives a Bayer quad.
            None => self,
        }
    }

    /// The phase with these colours in reading order, if they form a Bayer quad.
    pub const fn from_quad(q: [CfaColour; 4]) -> Option<Self> {
        use CfaColour::{Blue as B, Green as G, Red as R};
        match q {
            [R, G, G, B] => Some(Self::Rggb),
            [B, G, G, R] => Some(Self::Bggr),
            [G, R, B, G] => Some(Self::Grbg),
            [G, B, R, G] => Some(Self::Gbrg),
            _ => None,
        }
    }

    /// The DNG `CFAPattern` bytes in reading order.
    pub const fn dng_pattern(self) -> [u8; 4] {
        let q = self.quad();
        [
            q[0].dng_code(),
            q[1].dng_code(),
            q[2].dng_code(),
            q[3].dng_code(),
        ]
    }

    /// Reading-order positions of red, the two greens and blue: `[r, g1, g2, b]` where `g1` is
    /// the first green in reading order.
    pub const fn positions(self) -> [usize; 4] {
        match self {
            Self::Rggb => [0, 1, 2, 3],
            Self::Bggr => [3, 1, 2, 0],
            Self::Grbg => [1, 0, 3, 2],
            Self::Gbrg => [2, 0, 3, 1],
        }
    }

    /// The upper-case name (`"RGGB"`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Rggb => "RGGB",
            Self::Bggr => "BGGR",
            Self::Grbg => "GRBG",
            Self::Gbrg => "GBRG",
        }
    }
}

impl fmt::Display for BayerPhase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_match_quad() {
        for p in BayerPhase::ALL {
            let q = p.quad();
            let [r, g1, g2, b] = p.positions();
            assert_eq!(q[r], CfaColour::Red);
            assert_eq!(q[g1], CfaColour::Green);
            assert_eq!(q[g2], CfaColour::Green);
            assert_eq!(q[b], CfaColour::Blue);
            assert!(g1 < g2);
        }
    }

    #[test]
    fn shifts_compose() {
        for p in BayerPhase::ALL {
            assert_eq!(p.shifted(0, 0), p);
            assert_eq!(p.shifted(1, 0).shifted(1, 0), p);
            assert_eq!(p.shifted(0, 1).shifted(0, 1), p);
            for y in 0..4 {
                for x in 0..4 {
                    assert_eq!(p.shifted(1, 1).colour_at(x, y), p.colour_at(x + 1, y + 1));
                }
            }
        }
        assert_eq!(BayerPhase::Rggb.shifted(1, 0), BayerPhase::Grbg);
        assert_eq!(BayerPhase::Rggb.shifted(0, 1), BayerPhase::Gbrg);
        assert_eq!(BayerPhase::Rggb.shifted(1, 1), BayerPhase::Bggr);
    }
}
