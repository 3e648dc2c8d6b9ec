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
        format!(
            "skinbrdf {:?} targets, tag36h11, print at 100 % (scale bar = 100 mm)",
            self.kind
        )
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
                cy + 0.5 * t.size_mm * 1.25 + 3.0,
                t.id
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
        let pt = 72.0 / 25.4;
        let (pw, ph) = (self.width_mm * pt, self.height_mm * pt);
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
                cy + 0.5 * t.size_mm * 1.25 + 3.0,
                2.5,
                &t.id.to_string(),
            );
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
        let objects = [
            "<< /Type /Catalog /Pages 2 0 R >>".to_string(),
            "<< /Type /Pages /Kids [3 0 R] /Count 1 >>".to_string(),
            format!(
                "<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {pw:.3} {ph:.3}] /Contents 4 0 R /Resources << /Font << /F1 5 0 R >> >> >>"
            ),
            format!(
                "<< /Length {} >>\nstream\n{content}endstream",
                content.len()
            ),
            "<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>".to_string(),
        ];
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
