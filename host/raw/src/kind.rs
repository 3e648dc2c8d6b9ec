//! A file's kind ([`FileKind`]): its names and the extensions it may carry. What a file is
//! from its content is [`crate::sniff`].

use std::fmt;

/// A file's kind, from its content.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FileKind {
    /// PNG.
    Png,
    /// JPEG (JFIF or EXIF).
    Jpeg,
    /// A TIFF image that is not a camera raw file.
    Tiff,
    /// OpenEXR.
    OpenExr,
    /// Adobe DNG.
    Dng,
    /// Canon CR2.
    Cr2,
    /// Canon CR3.
    Cr3,
    /// Canon CRW.
    Crw,
    /// Nikon NEF.
    Nef,
    /// Nikon NRW.
    Nrw,
    /// Sony ARW (also SRF, SR2).
    Arw,
    /// Fujifilm RAF.
    Raf,
    /// Panasonic / Leica RW2 (also RWL, RAW).
    Rw2,
    /// Olympus / OM System ORF.
    Orf,
    /// Pentax / Ricoh PEF.
    Pef,
    /// Samsung SRW.
    Srw,
    /// Minolta MRW.
    Mrw,
    /// Sigma X3F (Foveon).
    X3f,
    /// Phase One / Leaf IIQ, MOS.
    Iiq,
    /// Another TIFF-based raw format (Kodak, Epson, Mamiya, Hasselblad...).
    OtherRaw,
}

impl FileKind {
    /// True for camera raw files (decoded by [`crate::decode_superpixel`]).
    pub const fn is_raw(self) -> bool {
        !matches!(self, Self::Png | Self::Jpeg | Self::Tiff | Self::OpenExr)
    }

    /// A short upper-case name (`"DNG"`, `"PNG"`, `"OpenEXR"`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Png => "PNG",
            Self::Jpeg => "JPEG",
            Self::Tiff => "TIFF",
            Self::OpenExr => "OpenEXR",
            Self::Dng => "DNG",
            Self::Cr2 => "CR2",
            Self::Cr3 => "CR3",
            Self::Crw => "CRW",
            Self::Nef => "NEF",
            Self::Nrw => "NRW",
            Self::Arw => "ARW",
            Self::Raf => "RAF",
            Self::Rw2 => "RW2",
            Self::Orf => "ORF",
            Self::Pef => "PEF",
            Self::Srw => "SRW",
            Self::Mrw => "MRW",
            Self::X3f => "X3F",
            Self::Iiq => "IIQ",
            Self::OtherRaw => "camera raw",
        }
    }

    /// The extensions (lower case, without the dot) a file of this kind may carry; empty for
    /// [`FileKind::OtherRaw`], whose extensions vary by maker.
    pub const fn extensions(self) -> &'static [&'static str] {
        match self {
            Self::Png => &["png"],
            Self::Jpeg => &["jpg", "jpeg", "jpe"],
            Self::Tiff => &["tif", "tiff"],
            Self::OpenExr => &["exr"],
            Self::Dng => &["dng"],
            Self::Cr2 => &["cr2"],
            Self::Cr3 => &["cr3"],
            Self::Crw => &["crw"],
            Self::Nef => &["nef"],
            Self::Nrw => &["nrw"],
            Self::Arw => &["arw", "srf", "sr2"],
            Self::Raf => &["raf"],
            Self::Rw2 => &["rw2", "rwl", "raw"],
            Self::Orf => &["orf"],
            Self::Pef => &["pef"],
            Self::Srw => &["srw"],
            Self::Mrw => &["mrw"],
            Self::X3f => &["x3f"],
            Self::Iiq => &["iiq", "mos"],
            Self::OtherRaw => &[],
        }
    }

    /// The kind an extension names (case-insensitive), if any.
    pub fn from_extension(ext: &str) -> Option<Self> {
        let ext = ext.to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|k| k.extensions().contains(&ext.as_str()))
    }

    /// Every kind.
    pub const ALL: [Self; 20] = [
        Self::Png,
        Self::Jpeg,
        Self::Tiff,
        Self::OpenExr,
        Self::Dng,
        Self::Cr2,
        Self::Cr3,
        Self::Crw,
        Self::Nef,
        Self::Nrw,
        Self::Arw,
        Self::Raf,
        Self::Rw2,
        Self::Orf,
        Self::Pef,
        Self::Srw,
        Self::Mrw,
        Self::X3f,
        Self::Iiq,
        Self::OtherRaw,
    ];
}

impl fmt::Display for FileKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
