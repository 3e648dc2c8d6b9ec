//! Printable target sheets at true scale (SVG and PDF) and their tag positions.
//!
//! Sheet frame: origin at the sheet's reference point (its centre; for the flash ring the centre
//! of the 82 mm disc), x right and y **up** on the printed page, z out of the paper towards the
//! viewer, millimetres. Tag sizes are the black square's edge (what the detector measures).
//! Every sheet carries a 100 mm scale bar to check the printer did not rescale.

use crate::tag36h11;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Which sheet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SheetKind {
    /// Tags for the headdress band (IDs 100..112, 15 mm).
    Headdress,
    /// The reference field (IDs 0..24, 30 mm).
    Reference,
    /// A ring around the flash's 82 mm disc (IDs 200..208, 12 mm).
    Flash,
    /// A calibration board (IDs 300..348, 20 mm).
    Board,
}

impl SheetKind {
    /// The kind's name in words (`headdress`, `reference`, `flash`, `board`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Headdress => "headdress",
            Self::Reference => "reference",
            Self::Flash => "flash",
            Self::Board => "board",
        }
    }
}

/// One tag on a sheet.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SheetTag {
    /// tag36h11 ID.
    pub id: u32,
    /// Centre in the sheet frame, mm (x right, y up).
    pub centre_mm: [f64; 2],
    /// Edge of the black square, mm.
    pub size_mm: f64,
}

/// A sheet: page size, tags and an optional circle (the flash disc outline).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sheet {
    /// Which sheet.
    pub kind: SheetKind,
    /// Page width, mm (A4 portrait).
    pub width_mm: f64,
    /// Page height, mm.
    pub height_mm: f64,
    /// The tags.
    pub tags: Vec<SheetTag>,
    /// Circle outline (centre = sheet origin), diameter mm.
    pub circle_diameter_mm: Option<f64>,
    /// For cut-out sheets ([`Sheet::cutouts`]): this page's number and the page count. Each
    /// tag then has a dashed cut line at its paper's edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutout_page: Option<(usize, usize)>,
}

/// Half extent of a cut-out target's paper in units of half the tag's black square: the black
/// border ends at 1, the tag's white ring at 1.25, and a quarter cell more of paper keeps the
/// ring clear of the mount's edge. The synthetic renderer paints targets with the same paper
/// (`skinbrdf_synth::photograph::PAPER_HALF_EXTENT`), so a printed rig matches the scenes.
pub const CUTOUT_PAPER_HALF_EXTENT: f64 = 1.5;
/// Space between neighbouring cut-outs, mm (room for scissors).
const CUTOUT_GAP_MM: f64 = 4.0;
/// Height of the ID label under each cut-out, mm.
const CUTOUT_LABEL_MM: f64 = 4.0;
/// Page margins of cut-out sheets, mm: sides and top; the bottom keeps 22 mm for the scale bar
/// and the title.
const CUTOUT_MARGIN_MM: f64 = 10.0;
const CUTOUT_BOTTOM_MM: f64 = 22.0;

/// Why a set of tags cannot be laid out as cut-outs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SheetError {
    /// A tag (with its paper) does not fit on an A4 page.
    #[error("tag {id}: {size_mm} mm does not fit on an A4 page with its paper")]
    TooLarge {
        /// The tag.
        id: u32,
        /// Its black square, mm.
        size_mm: f64,
    },
    /// A size that is not a positive finite number.
    #[error("tag {id}: size {size_mm} mm is not positive")]
    BadSize {
        /// The tag.
        id: u32,
        /// The size given.
        size_mm: f64,
    },
    /// An ID outside the tag36h11 family.
    #[error("tag {0} is not in tag36h11 (IDs 0..587)")]
    BadId(u32),
}

/// A4 portrait.
const A4: (f64, f64) = (210.0, 297.0);

fn grid(first: u32, cols: usize, rows: usize, size: f64, pitch: f64) -> Vec<SheetTag> {
    let mut v = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let x = (c as f64 - (cols as f64 - 1.0) / 2.0) * pitch;
            let y = ((rows as f64 - 1.0) / 2.0 - r as f64) * pitch;
            v.push(SheetTag {
                id: first + (r * cols + c) as u32,
                centre_mm: [x, y],
                size_mm: size,
            });
        }
    }
    v
}

impl Sheet {
    /// The standard sheet of a kind.
    pub fn standard(kind: SheetKind) -> Self {
        let (tags, circle) = match kind {
            SheetKind::Reference => (grid(0, 4, 6, 30.0, 43.0), None),
            SheetKind::Headdress => (grid(100, 4, 3, 15.0, 26.0), None),
            SheetKind::Board => (grid(300, 6, 8, 20.0, 29.0), None),
            SheetKind::Flash => {
                let r = 41.0 + 13.0;
                let tags = (0..8)
                    .map(|i| {
                        let a = i as f64 * std::f64::consts::FRAC_PI_4;
                        SheetTag {
                            id: 200 + i,
                            centre_mm: [r * a.cos(), r * a.sin()],
                            size_mm: 12.0,
                        }
                    })
                    .collect();
                (tags, Some(82.0))
            }
        };
        Self {
            kind,
            width_mm: A4.0,
            height_mm: A4.1,
            tags,
            circle_diameter_mm: circle,
            cutout_page: None,
        }
    }

    /// Tags to cut out and mount one by one (a reference cage, a headdress of separate tags),
    /// `(id, black square edge in mm)` each, packed in rows on as many A4 pages as needed (in
    /// the order given). Each tag has a dashed cut line at its paper's edge
    /// ([`CUTOUT_PAPER_HALF_EXTENT`]) and its ID below; the layout file says where it goes.
    pub fn cutouts(kind: SheetKind, tags: &[(u32, f64)]) -> Result<Vec<Self>, SheetError> {
        let (w, h) = A4;
        let usable_w = w - 2.0 * CUTOUT_MARGIN_MM;
        let usable_h = h - CUTOUT_MARGIN_MM - CUTOUT_BOTTOM_MM;
        let mut pages: Vec<Vec<SheetTag>> = vec![Vec::new()];
        // Cursor: left edge of the next cut-out, top of the current row, row height (page mm).
        let (mut x, mut top, mut row_h) = (0.0, 0.0, 0.0f64);
        for &(id, size_mm) in tags {
            if !(size_mm.is_finite() && size_mm > 0.0) {
                return Err(SheetError::BadSize { id, size_mm });
            }
            if id as usize >= tag36h11::NUM_TAGS {
                return Err(SheetError::BadId(id));
            }
            let paper = 2.0 * CUTOUT_PAPER_HALF_EXTENT * 0.5 * size_mm;
            let (cw, ch) = (paper, paper + CUTOUT_LABEL_MM);
            if cw > usable_w || ch > usable_h {
                return Err(SheetError::TooLarge { id, size_mm });
            }
            if x + cw > usable_w {
                (x, top, row_h) = (0.0, top + row_h + CUTOUT_GAP_MM, 0.0);
            }
            if top + ch > usable_h {
                pages.push(Vec::new());
                (x, top, row_h) = (0.0, 0.0, 0.0);
            }
            // Sheet frame: origin at the page centre, y up.
            let (px, py) = (
                CUTOUT_MARGIN_MM + x + 0.5 * paper,
                CUTOUT_MARGIN_MM + top + 0.5 * paper,
            );
            if let Some(page) = pages.last_mut() {
                page.push(SheetTag {
                    id,
                    centre_mm: [px - 0.5 * w, 0.5 * h - py],
                    size_mm,
                });
            }
            x += cw + CUTOUT_GAP_MM;
            row_h = row_h.max(ch);
        }
        let n = pages.len();
        Ok(pages
            .into_iter()
            .enumerate()
            .map(|(i, tags)| Self {
                kind,
                width_mm: w,
                height_mm: h,
                tags,
                circle_diameter_mm: None,
                cutout_page: Some((i + 1, n)),
            })
            .collect())
    }

    /// Dashed cut lines of a cut-out sheet: page squares `(x, y, edge)` in mm (y down).
    fn cut_squares(&self) -> Vec<(f64, f64, f64)> {
        if self.cutout_page.is_none() {
            return Vec::new();
        }
        self.tags
            .iter()
            .map(|t| {
                let half = CUTOUT_PAPER_HALF_EXTENT * 0.5 * t.size_mm;
                let (cx, cy) = self.page(t.centre_mm[0], t.centre_mm[1]);
                (cx - half, cy - half, 2.0 * half)
            })
            .collect()
    }

    /// Where a tag's ID label goes (page mm, y down: the label's baseline).
    fn label_y(&self, t: &SheetTag, cy: f64) -> f64 {
        if self.cutout_page.is_some() {
            cy + CUTOUT_PAPER_HALF_EXTENT * 0.5 * t.size_mm + 3.0
        } else {
            cy + 0.5 * t.size_mm * 1.25 + 3.0
        }
    }

    /// Page coordinates (mm, origin top-left, y down) of a sheet-frame point.
    fn page(&self, x: f64, y: f64) -> (f64, f64) {
        (self.width_mm / 2.0 + x, self.height_mm / 2.0 - y)
    }

    /// Black cells of every tag as page rectangles `(x, y, w, h)` in mm (y down), merged per row.
    fn black_rects(&self) -> Vec<(f64, f64, f64, f64)> {
        let mut out = Vec::new();
        for t in &self.tags {
            let Some(bits) = tag36h11::tag_bits(t.id as usize) else {
                continue;
            };
            let cell = t.size_mm / tag36h11::WIDTH_AT_BORDER as f64;
            let (cx, cy) = self.page(t.centre_mm[0], t.centre_mm[1]);
            let x0 = cx - 5.0 * cell;
            let y0 = cy - 5.0 * cell;
            for (r, row) in bits.iter().enumerate() {
                let mut c = 0;
                while c < 10 {
                    if row[c] {
                        c += 1;
                        continue;
                    }
                    let start = c;
                    while c < 10 && !row[c] {
                        c += 1;
                    }
                    out.push((
                        x0 + start as f64 * cell,
                        y0 + r as f64 * cell,
                        (c - start) as f64 * cell,
                        cell,
                    ));
                }
            }
        }
        out
    }

    fn title(&self) -> String {
        match self.cutout_page {
            Some((i, n)) => format!(
                "skinbrdf {} targets to cut out, page {i} of {n}, tag36h11, print at 100 % (scale bar = 100 mm)",
                self.kind.name()
            ),
            None => format!(
                "skinbrdf {} targets, tag36h11, print at 100 % (scale bar = 100 mm)",
                self.kind.name()
            ),
        }
    }

    /// The sheet as SVG at true scale (`width="210mm"`, user units = mm).
    pub fn to_svg(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" viewBox="0 0 {w} {h}">"#,
            w = self.width_mm,
            h = self.height_mm
        );
        let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
        for (x, y, w, h) in self.black_rects() {
            // A hair of overlap hides anti-aliasing seams between adjacent cells.
            let _ = writeln!(
                s,
                r#"<rect x="{x:.4}" y="{y:.4}" width="{:.4}" height="{:.4}" fill="black"/>"#,
                w + 0.01,
                h + 0.01
            );
        }
        for t in &self.tags {
            let (cx, cy) = self.page(t.centre_mm[0], t.centre_mm[1]);
            let _ = writeln!(
                s,
                r#"<text x="{cx:.3}" y="{:.3}" font-family="Helvetica" font-size="2.5" text-anchor="middle">{}</text>"#,
                self.label_y(t, cy),
                t.id
            );
        }
        for (x, y, e) in self.cut_squares() {
            let _ = writeln!(
                s,
                r#"<rect x="{x:.3}" y="{y:.3}" width="{e:.3}" height="{e:.3}" fill="none" stroke="gray" stroke-width="0.15" stroke-dasharray="1.5 1"/>"#
            );
        }
        if let Some(d) = self.circle_diameter_mm {
            let (cx, cy) = self.page(0.0, 0.0);
            let _ = writeln!(
                s,
                r#"<circle cx="{cx}" cy="{cy}" r="{}" fill="none" stroke="black" stroke-width="0.2" stroke-dasharray="2 1"/>"#,
                d / 2.0
            );
        }
        let _ = writeln!(
            s,
            r#"<rect x="10" y="{}" width="100" height="1.5" fill="black"/>"#,
            self.height_mm - 12.0
        );
        let _ = writeln!(
            s,
            r#"<text x="10" y="{}" font-family="Helvetica" font-size="3">{}</text>"#,
            self.height_mm - 5.0,
            self.title()
        );
        s.push_str("</svg>\n");
        s
    }

    /// The sheet as a one-page PDF at true scale (vector rectangles, Helvetica text).
    pub fn to_pdf(&self) -> Vec<u8> {
        pdf_document(std::slice::from_ref(self))
    }

    /// The page's PDF content stream (points, y up).
    fn pdf_content(&self) -> String {
        let pt = 72.0 / 25.4;
        let ph = self.height_mm * pt;
        let mut content = String::new();
        content.push_str("0 g\n");
        // PDF y is up from the bottom.
        let rect = |c: &mut String, x: f64, y: f64, w: f64, h: f64| {
            let _ = writeln!(
                c,
                "{:.3} {:.3} {:.3} {:.3} re f",
                x * pt,
                ph - (y + h) * pt,
                w * pt,
                h * pt
            );
        };
        for (x, y, w, h) in self.black_rects() {
            rect(&mut content, x, y, w + 0.01, h + 0.01);
        }
        rect(&mut content, 10.0, self.height_mm - 12.0, 100.0, 1.5);
        let text = |c: &mut String, x: f64, y: f64, size: f64, s: &str| {
            let esc = s
                .replace('\\', "\\\\")
                .replace('(', "\\(")
                .replace(')', "\\)");
            let _ = writeln!(
                c,
                "BT /F1 {:.2} Tf {:.3} {:.3} Td ({esc}) Tj ET",
                size * pt,
                x * pt,
                ph - y * pt
            );
        };
        for t in &self.tags {
            let (cx, cy) = self.page(t.centre_mm[0], t.centre_mm[1]);
            text(
                &mut content,
                cx - 2.0,
                self.label_y(t, cy),
                2.5,
                &t.id.to_string(),
            );
        }
        let cuts = self.cut_squares();
        if !cuts.is_empty() {
            content.push_str("q 0.5 G 0.4 w [4 3] 0 d\n");
            for (x, y, e) in cuts {
                let _ = writeln!(
                    content,
                    "{:.3} {:.3} {:.3} {:.3} re S",
                    x * pt,
                    ph - (y + e) * pt,
                    e * pt,
                    e * pt
                );
            }
            content.push_str("Q\n");
        }
        text(&mut content, 10.0, self.height_mm - 5.0, 3.0, &self.title());
        if let Some(d) = self.circle_diameter_mm {
            // Circle from four Bezier arcs.
            let (cx, cy) = self.page(0.0, 0.0);
            let (cx, cy, r) = (cx * pt, ph - cy * pt, d / 2.0 * pt);
            let k = 0.552_284_749_8 * r;
            let _ = writeln!(
                content,
                "0.5 w {x0:.3} {cy:.3} m {x0:.3} {a:.3} {b:.3} {y1:.3} {cx:.3} {y1:.3} c {c2:.3} {y1:.3} {x2:.3} {a:.3} {x2:.3} {cy:.3} c {x2:.3} {d2:.3} {c2:.3} {y0:.3} {cx:.3} {y0:.3} c {b:.3} {y0:.3} {x0:.3} {d2:.3} {x0:.3} {cy:.3} c S",
                x0 = cx - r,
                x2 = cx + r,
                y0 = cy - r,
                y1 = cy + r,
                a = cy + k,
                d2 = cy - k,
                b = cx - k,
                c2 = cx + k,
            );
        }
        content
    }
}

/// Sheets as one PDF, a page each (A4, true scale).
pub fn pdf_document(sheets: &[Sheet]) -> Vec<u8> {
    let pt = 72.0 / 25.4;
    // Objects: 1 catalog, 2 pages, 3 font, then (page, content) per sheet.
    let kids: Vec<String> = (0..sheets.len())
        .map(|i| format!("{} 0 R", 4 + 2 * i))
        .collect();
    let mut objects = vec![
        "<< /Type /Catalog /Pages 2 0 R >>".to_string(),
        format!(
            "<< /Type /Pages /Kids [{}] /Count {} >>",
            kids.join(" "),
            sheets.len()
        ),
        "<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>".to_string(),
    ];
    for (i, sh) in sheets.iter().enumerate() {
        let (pw, ph) = (sh.width_mm * pt, sh.height_mm * pt);
        let content = sh.pdf_content();
        objects.push(format!(
            "<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {pw:.3} {ph:.3}] /Contents {} 0 R /Resources << /Font << /F1 3 0 R >> >> >>",
            5 + 2 * i
        ));
        objects.push(format!(
            "<< /Length {} >>\nstream\n{content}endstream",
            content.len()
        ));
    }
    let mut out = b"%PDF-1.4\n".to_vec();
    let mut offsets = Vec::new();
    for (i, o) in objects.iter().enumerate() {
        offsets.push(out.len());
        out.extend_from_slice(format!("{} 0 obj\n{o}\nendobj\n", i + 1).as_bytes());
    }
    let xref = out.len();
    let mut x = format!("xref\n0 {}\n0000000000 65535 f \n", objects.len() + 1);
    for off in offsets {
        let _ = writeln!(x, "{off:010} 00000 n ");
    }
    let _ = write!(
        x,
        "trailer\n<< /Size {} /Root 1 0 R >>\nstartxref\n{xref}\n%%EOF\n",
        objects.len() + 1
    );
    out.extend_from_slice(x.as_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cutouts_pack_every_tag_once_on_the_page_without_overlap() {
        // A cage of 40 tags of 35 mm and a few of 25 mm: several pages.
        let tags: Vec<(u32, f64)> = (0..40)
            .map(|i| (i, 35.0))
            .chain((100..106).map(|i| (i, 25.0)))
            .collect();
        let pages = Sheet::cutouts(SheetKind::Reference, &tags).expect("cutouts");
        assert!(pages.len() >= 3, "{} pages", pages.len());
        let mut seen: Vec<u32> = Vec::new();
        for (i, p) in pages.iter().enumerate() {
            assert_eq!(p.cutout_page, Some((i + 1, pages.len())));
            let cuts = p.cut_squares();
            assert_eq!(cuts.len(), p.tags.len());
            for (k, &(x, y, e)) in cuts.iter().enumerate() {
                // On the page, clear of the scale bar and title.
                assert!(x >= 5.0 && x + e <= p.width_mm - 5.0, "{:?}", p.tags[k]);
                assert!(
                    y >= 5.0 && y + e + 4.0 <= p.height_mm - 20.0,
                    "{:?}",
                    p.tags[k]
                );
                // No two papers (with their labels) overlap.
                for &(x2, y2, e2) in &cuts[..k] {
                    let apart =
                        x + e <= x2 || x2 + e2 <= x || y + e + 4.0 <= y2 || y2 + e2 + 4.0 <= y;
                    assert!(apart, "page {i}: {x},{y} and {x2},{y2}");
                }
            }
            seen.extend(p.tags.iter().map(|t| t.id));
            assert!(p.to_svg().contains("stroke-dasharray"));
        }
        assert_eq!(seen, tags.iter().map(|t| t.0).collect::<Vec<_>>());
        let pdf = pdf_document(&pages);
        let text = String::from_utf8_lossy(&pdf);
        assert!(text.contains(&format!("/Count {}", pages.len())));
        assert_eq!(text.matches("/Type /Page ").count(), pages.len());
        // Bad input is named.
        assert_eq!(
            Sheet::cutouts(SheetKind::Reference, &[(3, 400.0)]),
            Err(SheetError::TooLarge {
                id: 3,
                size_mm: 400.0
            })
        );
        assert_eq!(
            Sheet::cutouts(SheetKind::Reference, &[(3, f64::NAN)])
                .map(|_| ())
                .unwrap_err()
                .to_string(),
            "tag 3: size NaN mm is not positive"
        );
        assert_eq!(
            Sheet::cutouts(SheetKind::Reference, &[(900, 20.0)]),
            Err(SheetError::BadId(900))
        );
    }

    #[test]
    fn sheets_fit_the_page_with_unique_ids() {
        for kind in [
            SheetKind::Headdress,
            SheetKind::Reference,
            SheetKind::Flash,
            SheetKind::Board,
        ] {
            let s = Sheet::standard(kind);
            let mut ids: Vec<u32> = s.tags.iter().map(|t| t.id).collect();
            ids.sort_unstable();
            ids.dedup();
            assert_eq!(ids.len(), s.tags.len());
            for t in &s.tags {
                // The whole tag including its white ring stays on the page with a 5 mm margin.
                let half = 0.5 * t.size_mm * 1.25;
                let (x, y) = s.page(t.centre_mm[0], t.centre_mm[1]);
                assert!(
                    x - half > 5.0 && x + half < s.width_mm - 5.0,
                    "{kind:?} {t:?}"
                );
                assert!(
                    y - half > 5.0 && y + half < s.height_mm - 20.0,
                    "{kind:?} {t:?}"
                );
            }
            assert!(s.to_svg().contains("width=\"210mm\""));
            let pdf = s.to_pdf();
            assert!(pdf.starts_with(b"%PDF-1.4") && pdf.ends_with(b"%%EOF\n"));
        }
    }

    #[test]
    fn flash_ring_clears_the_disc() {
        let s = Sheet::standard(SheetKind::Flash);
        for t in &s.tags {
            let r = (t.centre_mm[0].powi(2) + t.centre_mm[1].powi(2)).sqrt();
            // The tag's nearest point (corner direction worst case) stays outside the disc.
            assert!(r - t.size_mm * 1.25 * std::f64::consts::FRAC_1_SQRT_2 > 41.0);
        }
    }
}
