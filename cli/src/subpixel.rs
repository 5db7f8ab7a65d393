//! `clatch colmap --subpixel`: how keypoint positions are refined for COLMAP
//! ([`clatch::colmap::Refinement`]).

/// How keypoint positions are refined for COLMAP.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Subpixel {
    /// Whole pixels, as detected.
    None,
    /// The library's [`clatch::Subpixel::Score`]: the peak of a parabola through the FAST scores of
    /// the keypoint and its 4 neighbours, per axis, on the keypoint's pyramid level.
    Score,
    /// Förstner's least-squares corner over a window of the photo
    /// ([`clatch::colmap::refine_corners`]).
    Corner,
}

impl Subpixel {
    /// The library's refinement, with `radius` the corner window's half side.
    pub fn refinement(self, radius: u32) -> clatch::colmap::Refinement {
        use clatch::colmap::Refinement;
        match self {
            Subpixel::None => Refinement::None,
            Subpixel::Score => Refinement::Score,
            Subpixel::Corner => Refinement::Corner { radius },
        }
    }
}
