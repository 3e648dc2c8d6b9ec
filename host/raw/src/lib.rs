//! Camera raw files for skinbrdf: what a file is ([`sniff`]), its radiometrically linear pixels
//! ([`decode_photosites`], [`decode_superpixel`]), its exposure metadata ([`read_metadata`]) and a DNG writer
//! ([`dng::write_dng`]) for the synthetic studio.
//!
//! [`decode_mosaic`] decodes a file once into its compact [`RawMosaic`] (the active area's
//! stored values with the levels and phase they are read with: two bytes per photosite of an
//! integer file), from which [`RawMosaic::frame`] gives either layout and
//! [`RawMosaic::photosite_row`] the photosite image's values, each the same as a decode's;
//! a run that keeps mosaics decodes each file once (`skinbrdf_session::DecodeCache`).
//! [`decodes_started`] counts the decodes this process started.
//!
//! # Radiometry
//!
//! Decoding is deliberately minimal, so the values stay proportional to the photosites' charge:
//! for each photosite of CFA position `c` (its place in the active area's 2x2 quad),
//!
//! ```text
//! n = (raw - black_c) / (white - black_c)
//! ```
//!
//! with no white balance, no colour matrix and no tone curve (the method's calibration constant
//! `C`, one per channel, absorbs the channel gains). `black_c` is the file's black level for
//! that CFA position; `white` is the file's white level. [`RawOptions`] may override either.
//!
//! # Photosites, superpixels and coordinates
//!
//! Pixel centres are at integer coordinates (the OpenCV convention) in both the sensor's active
//! area and the image as loaded. Two layouts ([`RawLayout`]):
//!
//! * **Photosites** ([`decode_photosites`], full resolution): output pixel `(x, y)` is
//!   active-area photosite `(x, y)`. It holds its own channel (the colour of its filter, from
//!   the phase at the active area's origin) normalised with its own CFA position's black level;
//!   the other two channels are NaN: they were not measured there, and no value is interpolated
//!   into them. The image's camera model is the sensor's (photosite units, no conversion).
//! * **Superpixels** ([`decode_superpixel`], half resolution, faster): output pixel `(u, v)` is
//!   the Bayer quad whose top-left photosite is `(2u, 2v)` *in the active area*: its red
//!   photosite, the mean of its two green photosites and its blue photosite. It covers
//!   photosites `2u..=2u+1` by `2v..=2v+1`, so its centre is at sensor (active-area)
//!   coordinates `(2u + 0.5, 2v + 0.5)`, while its red and blue values were measured half a
//!   photosite from there in x and y. A calibration made on the full sensor converts with
//!   [`sensor_to_superpixel_focal`] (`f' = f / 2`) and [`sensor_to_superpixel_centre`]
//!   (`c' = (c - 0.5) / 2`), or as a whole with [`sensor_camera_to_superpixel`];
//!   [`superpixel_camera_to_sensor`] is the inverse (`f = 2 f'`, `c = 2 c' + 0.5`).
//!
//! An active area of odd width or height drops its last column or row in both layouts, so the
//! photosite image is exactly twice the superpixel image. Every image-space quantity of the
//! pipeline (intrinsics, detections, derendering) refers to the image *as loaded*.
//!
//! A superpixel is *saturated* when any of its four photosites' raw value is at or above the
//! white level; a photosite when its own raw value is.
//!
//! # Layouts
//!
//! All four Bayer phases ([`BayerPhase`]) are supported, whatever the parity of the active
//! area's origin. X-Trans, other CFA patterns and linear (non-mosaic, e.g. Foveon or linear DNG)
//! data are refused with [`RawError::UnsupportedLayout`], naming the file and the layout.

mod assemble;
mod bayer;
mod decode;
pub mod dng;
mod error;
mod exposure;
mod frame;
mod identify;
mod isolate;
mod kind;
mod limits;
mod meta;
mod mosaic;
pub mod tiff;
mod via_libraw;

pub use bayer::{BayerPhase, CfaColour};
pub use decode::{
    decode_mosaic, decode_photosites, decode_raw, decode_superpixel, decodes_started,
    read_raw_header,
};
pub use error::RawError;
pub use exposure::{CaptureTime, ExposureMeta, LocalDateTime};
pub use frame::{
    sensor_camera_to_superpixel, sensor_to_superpixel_centre, sensor_to_superpixel_focal,
    superpixel_camera_to_sensor, superpixel_to_sensor_centre, superpixel_to_sensor_focal, RawFrame,
    RawHeader, RawLayout, RawOptions,
};
pub use identify::{check_extension, sniff};
pub use isolate::{
    decoded_size_with, read_metadata_with, worker_main, Isolation, WorkerOp,
    DEFAULT_MAX_MEMORY_BYTES, DEFAULT_TIMEOUT, WORKER_REFUSED,
};
pub use kind::FileKind;
pub use limits::{MAX_IFDS, MAX_IFD_ENTRIES, MAX_PIXELS, VALUE_BYTES_PER_FILE_BYTE};
pub use meta::{focal_plane_unit_mm, read_metadata, FULL_FRAME_DIAGONAL_MM};
pub use mosaic::{MosaicSamples, RawMosaic, SampleType};
