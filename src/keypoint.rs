//! Keypoints, in OpenCV's vocabulary.

/// A detected (or caller-supplied) keypoint.
///
/// Conventions follow OpenCV's `cv::KeyPoint`: pixel centres sit at integer coordinates, `x` to the right,
/// `y` down; `angle` is in degrees, measured from the +x axis towards +y (clockwise on screen).
/// `size` is the side of the descriptor window in pixels: the 64x64 sample window is spread over
/// `size` x `size` pixels, so the default 64 samples every pixel once.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct KeyPoint {
    /// Column of the keypoint centre, in pixels.
    pub x: f32,
    /// Row of the keypoint centre, in pixels.
    pub y: f32,
    /// Side of the descriptor window, in pixels (default [`KeyPoint::DEFAULT_SIZE`]).
    pub size: f32,
    /// Orientation in degrees; the descriptor window is rotated by it.
    pub angle: f32,
    /// Detector strength (the FAST score for detected keypoints); larger is stronger.
    pub response: f32,
    /// Pyramid level the keypoint was found on (0: full resolution).
    pub octave: i32,
}

/// The window side given to detected keypoints: one sample per pixel.
pub const DEFAULT_KEYPOINT_SIZE: f32 = 64.0;

impl KeyPoint {
    /// The window side given to detected keypoints: one sample per pixel (64).
    pub const DEFAULT_SIZE: f32 = DEFAULT_KEYPOINT_SIZE;

    /// An upright keypoint of the default size at `(x, y)`.
    pub fn new(x: f32, y: f32) -> Self {
        Self {
            x,
            y,
            size: DEFAULT_KEYPOINT_SIZE,
            angle: 0.0,
            response: 0.0,
            octave: 0,
        }
    }

    /// The same keypoint with another orientation (degrees).
    pub fn with_angle(self, angle: f32) -> Self {
        Self { angle, ..self }
    }

    /// The same keypoint with another window side (pixels).
    pub fn with_size(self, size: f32) -> Self {
        Self { size, ..self }
    }
}
