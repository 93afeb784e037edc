//! The thermal frame pipeline of paper 003 (Chen et al.), Sec. 2.3-2.4, on kornia-rs:
//! decode radiometric frames ([`frame`]), undistort them and relate pixels to the printing
//! plane ([`camera`]), find the hot corners of the freshly printed path ([`corners`]),
//! match them to the known path corners ([`matching`]), place each matched corner on its path
//! vertex by intersecting the two bead ridges ([`vertex`]), estimate each frame's homography
//! (eq. 27, [`homography`]), localize the frame in time (eqs 29-30, [`localize`]) and
//! extract the left/right deposited half-widths along the deposition directions
//! (Sec. 2.4, [`widths`]); [`pipeline`] runs one frame end to end, and
//! [`sequence_widths`] reads every sample of a localised sequence in one frame at one
//! bead age, at a threshold T_t calibrated per layer on straight samples.
//!
//! Our extension of Sec. 2.3: the camera is rigid on a head that only translates, so one
//! mount homography fitted to the whole sequence ([`mount`]) and one translation per
//! frame replace the per-frame homography; [`rigid`] localises a frame that way from any
//! number of corners, one included. [`localiser`] runs both estimators over a whole
//! filmed sequence (the mount's fit-and-re-pair rounds, dead reckoning of frames without
//! corners, repeated and parked frames), reading the frames through a trait a dataset
//! reader implements.
//!
//! For paper 000 (FDM line width, Sec. III), [`lines`] measures the width of a single
//! printed line along its length from a top-view photo, to a fraction of a pixel, by
//! fitting a blurred-edge model to each cross-section (with an Otsu-count baseline).
//!
//! For real photos of printed patterns with the G-code that printed them, [`photo`] places
//! the photo on the bed (colour contrast, coarse pose, homography and radial distortion by
//! coarse-to-fine ECC, orientation from the print) and measures every path in bed mm.
//!
//! The crate takes plain slices and structs: no tables, no datasets, no I/O beyond
//! reading a frame file.
#![deny(missing_docs)]

pub mod camera;
pub mod corners;
pub mod frame;
pub mod homography;
pub mod lines;
pub mod localiser;
pub mod localize;
pub mod matching;
pub mod mount;
pub mod photo;
pub mod pipeline;
pub mod rigid;
pub mod sequence_widths;
pub mod synth;
pub mod vertex;
pub mod widths;
