//! Inputs of `skinbrdf fit` and `skinbrdf compare` ([`load_input`]): a sample file (`.skbs`), a
//! Cornell `.brdf` file (converted to linear sRGB under D65), or a session directory
//! (`DIR/out/samples.skbs`, or the only `.skbs` in `DIR` or `DIR/out`; `DIR/truth.json`, when
//! present, supplies the true BRDF for scoring).

use std::path::{Path, PathBuf};

use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::BrdfSample;
use skinbrdf_samples::{CornellBrdf, Illuminant};

use crate::report::ReportError;

/// A loaded input.
#[derive(Debug, Clone)]
pub struct Input {
    /// Where it came from.
    pub path: PathBuf,
    /// Short label (file or directory name).
    pub label: String,
    /// The samples (linear sRGB, 1/sr).
    pub samples: Vec<BrdfSample>,
    /// The Cornell grid, if the input was a `.brdf` file.
    pub cornell: Option<CornellBrdf>,
    /// The true BRDF, if a `truth.json` was found.
    pub truth: Option<BrdfModel>,
}

fn find_skbs(dir: &Path) -> Option<PathBuf> {
    let direct = dir.join("out").join("samples.skbs");
    if direct.is_file() {
        return Some(direct);
    }
    for d in [dir.to_path_buf(), dir.join("out")] {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let found: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "skbs"))
            .collect();
        if found.len() == 1 {
            return found.into_iter().next();
        }
    }
    None
}

/// The true BRDF of a synthetic session: the `brdf` field of its `truth.json`.
fn read_truth(path: &Path) -> Result<BrdfModel, ReportError> {
    let text = std::fs::read_to_string(path).map_err(|source| ReportError::TruthRead {
        path: path.to_path_buf(),
        source,
    })?;
    let json_err = |field, source| ReportError::TruthJson {
        path: path.to_path_buf(),
        field,
        source,
    };
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| json_err(None, Some(e)))?;
    let brdf = v
        .get("brdf")
        .cloned()
        .ok_or_else(|| json_err(Some("brdf"), None))?;
    serde_json::from_value(brdf).map_err(|e| json_err(Some("brdf"), Some(e)))
}

/// Loads a sample file, Cornell file or session directory.
pub fn load_input(path: &Path) -> Result<Input, ReportError> {
    let label = path.file_stem().map_or_else(
        || path.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    if path.is_dir() {
        let skbs = find_skbs(path).ok_or_else(|| ReportError::NoSamples {
            dir: path.to_path_buf(),
        })?;
        let (_, samples) = skinbrdf_samples::read_samples(&skbs)?;
        let truth_path = path.join("truth.json");
        let truth = if truth_path.is_file() {
            Some(read_truth(&truth_path)?)
        } else {
            None
        };
        return Ok(Input {
            path: path.to_path_buf(),
            label,
            samples,
            cornell: None,
            truth,
        });
    }
    if !path.is_file() {
        return Err(ReportError::NotFound {
            path: path.to_path_buf(),
        });
    }
    if path
        .extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("brdf"))
    {
        let c = CornellBrdf::read(path)?;
        let conv = c.rgb_converter(Illuminant::D65, path)?;
        let samples = c.to_rgb_samples(&conv);
        return Ok(Input {
            path: path.to_path_buf(),
            label,
            samples,
            cornell: Some(c),
            truth: None,
        });
    }
    let (_, samples) = skinbrdf_samples::read_samples(path)?;
    Ok(Input {
        path: path.to_path_buf(),
        label,
        samples,
        cornell: None,
        truth: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_inputs_are_named() {
        let e = load_input(Path::new("/nonexistent/x.skbs")).expect_err("missing");
        assert!(e.to_string().contains("/nonexistent/x.skbs"));
        let dir = tempfile::tempdir().expect("tempdir");
        let e = load_input(dir.path()).expect_err("empty dir");
        assert!(e.to_string().contains("no samples found"));
    }

    #[test]
    fn a_bad_truth_file_is_named_with_its_problem() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir(dir.path().join("out")).expect("out");
        let (_, samples) = crate::synthetic::lafortune2_samples(20, 0.0, 1);
        let header = skinbrdf_samples::SampleHeader::new("test", "truth errors");
        skinbrdf_samples::write_samples(dir.path().join("out/samples.skbs"), &header, &samples)
            .expect("samples");
        let truth = dir.path().join("truth.json");
        for (text, expected) in [
            ("{", "not JSON"),
            ("{}", "field `brdf` is missing or not a BRDF model"),
            (
                "{\"brdf\": 3}",
                "field `brdf` is missing or not a BRDF model",
            ),
        ] {
            std::fs::write(&truth, text).expect("truth");
            let e = load_input(dir.path()).expect_err(text);
            assert_eq!(e.to_string(), format!("{}: {expected}", truth.display()));
        }
        std::fs::write(
            &truth,
            "{\"brdf\": {\"model\": \"lambertian\", \"albedo\": [0.1, 0.2, 0.3]}}",
        )
        .expect("truth");
        let ok = load_input(dir.path()).expect("valid truth");
        assert!(ok.truth.is_some() && ok.samples.len() == 20);
    }
}
