//! The FFI boundary: one LibRaw instance, the bytes it reads and the EXIF tags its callback
//! recorded. Every `unsafe` block of the crate is here.
//!
//! Invariants of [`Handle`]: `ptr` is a live `libraw_data_t` from `libraw_init`, closed once
//! in `Drop`; `bytes` (the buffer given to `libraw_open_buffer`, which LibRaw reads lazily)
//! and `exif` (the callback's context) are boxed so their addresses stay fixed, and are
//! dropped only after `libraw_close` (fields drop after `Drop::drop`).

use std::ffi::{c_char, c_int, c_uint, c_void, CStr};
use std::ptr::NonNull;

use rsraw_sys as sys;

use crate::error::Failure;
use crate::exif::{ExifTags, TagAt, MAX_ENTRIES};

extern "C" {
    /// `shim/stream_tell.cpp`: the position of LibRaw's input stream (`-1` for null).
    fn skinbrdf_libraw_stream_tell(stream: *mut c_void) -> i64;
}

/// LibRaw's version string.
pub(crate) fn version() -> String {
    // SAFETY: libraw_version returns a pointer to a static NUL-terminated string.
    let text = unsafe { CStr::from_ptr(sys::libraw_version()) };
    text.to_string_lossy().into_owned()
}

/// LibRaw's words for an error code.
fn message(code: c_int) -> String {
    // SAFETY: libraw_strerror returns a pointer to a static NUL-terminated string for any code.
    let text = unsafe { CStr::from_ptr(sys::libraw_strerror(code)) };
    text.to_string_lossy().into_owned()
}

/// The callback LibRaw calls for every TIFF/EXIF directory entry it parses.
///
/// It must not unwind into C++: it only compares integers and pushes into a `Vec` that is
/// bounded by [`MAX_ENTRIES`].
unsafe extern "C" fn on_exif_entry(
    context: *mut c_void,
    tag: c_int,
    type_: c_int,
    len: c_int,
    _order: c_uint,
    stream: *mut c_void,
    _base: sys::INT64,
) {
    let tag = tag as u32;
    if context.is_null() || !ExifTags::wants(tag) {
        return;
    }
    // SAFETY: `context` is the `Box<ExifTags>` of the Handle whose open is running (set in
    // Handle::open, which holds the only other reference and does not touch it during the
    // call); LibRaw calls back on the opening thread only.
    let tags = unsafe { &mut *context.cast::<ExifTags>() };
    if tags.entries.len() >= MAX_ENTRIES {
        return;
    }
    // SAFETY: `stream` is the LibRaw_abstract_datastream LibRaw passes to its EXIF
    // callback, standing at the entry's value; the shim only calls its `tell`.
    let offset = unsafe { skinbrdf_libraw_stream_tell(stream) };
    tags.entries.push(TagAt {
        tag,
        type_,
        count: len,
        offset,
    });
}

/// Data errors LibRaw reported through its data-error callback (instead of printing them).
#[derive(Debug, Default)]
pub(crate) struct DataErrors {
    /// How many were reported.
    pub count: u32,
    /// The first one's byte offset (`None`: the data ended early).
    pub first_offset: Option<i64>,
}

/// The callback LibRaw calls when the image data is corrupt (`offset >= 0`) or ends early
/// (`offset < 0`). It must not unwind into C++: it only updates two integers.
unsafe extern "C" fn on_data_error(context: *mut c_void, _file: *const c_char, offset: c_int) {
    if context.is_null() {
        return;
    }
    // SAFETY: `context` is the `Box<DataErrors>` of the Handle whose open or unpack is
    // running, which does not touch it during the call; LibRaw calls back on that thread.
    let errors = unsafe { &mut *context.cast::<DataErrors>() };
    if errors.count == 0 {
        errors.first_offset = (offset >= 0).then_some(i64::from(offset));
    }
    errors.count = errors.count.saturating_add(1);
}

/// The values of LibRaw's state this crate uses, copied out.
#[derive(Debug, Clone)]
pub(crate) struct State {
    pub raw_width: u32,
    pub raw_height: u32,
    pub width: u32,
    pub height: u32,
    pub left_margin: u32,
    pub top_margin: u32,
    pub make: String,
    pub model: String,
    pub filters: u32,
    pub colors: i32,
    pub is_foveon: bool,
    /// Colour names by colour index (`cdesc`), e.g. `RGBG`.
    pub cdesc: [u8; 4],
    pub black: u32,
    /// `cblack[0..6]` and the per-position pattern after it (`cblack[4] * cblack[5]` values).
    pub cblack: Vec<u32>,
    pub maximum: u32,
    pub iso_speed: f32,
    pub shutter_s: f32,
    pub aperture: f32,
    pub focal_len_mm: f32,
    pub timestamp_s: i64,
}

/// A NUL-terminated C string in a fixed array, as text.
fn c_text(chars: &[c_char]) -> String {
    let bytes: Vec<u8> = chars
        .iter()
        .map(|c| *c as u8)
        .take_while(|b| *b != 0)
        .collect();
    String::from_utf8_lossy(&bytes).trim().to_string()
}

/// One LibRaw instance and what it reads.
#[derive(Debug)]
pub(crate) struct Handle {
    ptr: NonNull<sys::libraw_data_t>,
    bytes: Box<[u8]>,
    exif: Box<ExifTags>,
    data_errors: Box<DataErrors>,
    unpacked: bool,
}

impl Drop for Handle {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from libraw_init and is closed only here, once.
        unsafe { sys::libraw_close(self.ptr.as_ptr()) };
    }
}

impl Handle {
    /// A LibRaw instance that identified `bytes` (libraw_open_buffer), with the EXIF
    /// callback recording the tags [`ExifTags::wants`].
    pub(crate) fn open(bytes: Vec<u8>) -> Result<Self, Failure> {
        // SAFETY: libraw_init with no flags allocates a fresh instance or returns null.
        let ptr = NonNull::new(unsafe { sys::libraw_init(0) }).ok_or(Failure::Init)?;
        let mut handle = Handle {
            ptr,
            bytes: bytes.into_boxed_slice(),
            exif: Box::default(),
            data_errors: Box::default(),
            unpacked: false,
        };
        let context: *mut ExifTags = &mut *handle.exif;
        // SAFETY: `ptr` is live; `context` points into the Box owned by `handle`, which
        // outlives the instance (see the module's invariants).
        unsafe {
            sys::libraw_set_exifparser_handler(
                handle.ptr.as_ptr(),
                Some(on_exif_entry),
                context.cast::<c_void>(),
            )
        };
        let errors: *mut DataErrors = &mut *handle.data_errors;
        // SAFETY: as above, for the data-error callback's context.
        unsafe {
            sys::libraw_set_dataerror_handler(
                handle.ptr.as_ptr(),
                Some(on_data_error),
                errors.cast::<c_void>(),
            )
        };
        // SAFETY: `ptr` is live; the buffer is owned by `handle`, stays at its address and
        // outlives the instance (see the module's invariants).
        let code = unsafe {
            sys::libraw_open_buffer(
                handle.ptr.as_ptr(),
                handle.bytes.as_ptr().cast::<c_void>(),
                handle.bytes.len(),
            )
        };
        if code != 0 {
            return Err(Failure::Code {
                code,
                message: message(code),
            });
        }
        Ok(handle)
    }

    /// The bytes LibRaw reads.
    pub(crate) fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The EXIF tags recorded while opening.
    pub(crate) fn exif(&self) -> &ExifTags {
        &self.exif
    }

    /// The instance's state, read in place.
    fn data(&self) -> &sys::libraw_data_t {
        // SAFETY: `ptr` is live for `&self`'s lifetime, and LibRaw changes it only inside
        // calls that take `&mut self` (open, unpack).
        unsafe { self.ptr.as_ref() }
    }

    /// The values this crate uses, copied out of LibRaw's state.
    pub(crate) fn state(&self) -> State {
        let d = self.data();
        let s = &d.sizes;
        let i = &d.idata;
        let c = &d.color;
        let pattern = (c.cblack[4] as usize).saturating_mul(c.cblack[5] as usize);
        let cblack_len = (6 + pattern).min(c.cblack.len());
        let mut cdesc = [0u8; 4];
        for (out, ch) in cdesc.iter_mut().zip(i.cdesc.iter()) {
            *out = *ch as u8;
        }
        State {
            raw_width: u32::from(s.raw_width),
            raw_height: u32::from(s.raw_height),
            width: u32::from(s.width),
            height: u32::from(s.height),
            left_margin: u32::from(s.left_margin),
            top_margin: u32::from(s.top_margin),
            make: c_text(&i.make),
            model: c_text(&i.model),
            filters: i.filters,
            colors: i.colors,
            is_foveon: i.is_foveon != 0,
            cdesc,
            black: c.black,
            cblack: c.cblack[..cblack_len].to_vec(),
            maximum: c.maximum,
            iso_speed: d.other.iso_speed,
            shutter_s: d.other.shutter,
            aperture: d.other.aperture,
            focal_len_mm: d.other.focal_len,
            timestamp_s: d.other.timestamp,
        }
    }

    /// Unpacks the image data (libraw_unpack), once; data errors LibRaw reports while unpacking
    /// (corrupt or missing image data) refuse it.
    pub(crate) fn unpack(&mut self) -> Result<(), Failure> {
        if self.unpacked {
            return Ok(());
        }
        *self.data_errors = DataErrors::default();
        // SAFETY: `ptr` is live and was opened; the buffer it reads is still owned.
        let code = unsafe { sys::libraw_unpack(self.ptr.as_ptr()) };
        if code != 0 {
            return Err(Failure::Code {
                code,
                message: message(code),
            });
        }
        if self.data_errors.count > 0 {
            return Err(Failure::Data {
                count: self.data_errors.count,
                first_offset: self.data_errors.first_offset,
            });
        }
        self.unpacked = true;
        Ok(())
    }

    /// The unpacked mosaic, `raw_width * raw_height` values row by row.
    pub(crate) fn raw_mosaic(&self) -> Result<Vec<u16>, Failure> {
        if !self.unpacked {
            return Err(Failure::Sizes("the image data was not unpacked".into()));
        }
        let raw = &self.data().rawdata;
        if raw.raw_image.is_null() {
            let layout = if !raw.color4_image.is_null() {
                "four colours per photosite"
            } else if !raw.color3_image.is_null() {
                "three colours per photosite (linear or Foveon data)"
            } else if !raw.float_image.is_null()
                || !raw.float3_image.is_null()
                || !raw.float4_image.is_null()
            {
                "floating-point data"
            } else {
                "no image data"
            };
            return Err(Failure::NotMosaic(layout));
        }
        let width = usize::from(raw.sizes.raw_width);
        let height = usize::from(raw.sizes.raw_height);
        let pitch_values = raw.sizes.raw_pitch as usize / 2;
        if pitch_values < width || width == 0 || height == 0 {
            return Err(Failure::Sizes(format!(
                "{width} x {height} photosites with rows of {} bytes",
                raw.sizes.raw_pitch
            )));
        }
        let mut out = Vec::with_capacity(width * height);
        for row in 0..height {
            // SAFETY: LibRaw allocated raw_image as raw_height rows of raw_pitch bytes
            // (raw_pitch >= 2 raw_width, checked above) and keeps it until the next unpack
            // or close, neither of which can run while `&self` is borrowed.
            let line =
                unsafe { std::slice::from_raw_parts(raw.raw_image.add(row * pitch_values), width) };
            out.extend_from_slice(line);
        }
        Ok(out)
    }
}
