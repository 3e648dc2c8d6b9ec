//! Checked JSON output: the one way the host turns a value into JSON, for a file or for stdout.
//!
//! JSON has no NaN and no infinity, and `serde_json` silently writes either as `null`. A reader
//! expecting a number then refuses the file (`invalid type: null, expected f64`), and an
//! `Option<f64>` reads it back as "not estimated", which is not what the writer meant either.
//! So every value is first walked by a serializer that writes nothing and fails at the first
//! non-finite `f32` or `f64`; the error names the file and the JSON path of the field
//! (`images[3].world_from_camera.sigma[2]`: fields and map keys after dots, indices in
//! brackets, an enum variant as the key JSON writes for it). Only a value that passes is written
//! by `serde_json`. A quantity that could not be estimated is stated as such by its type
//! (`Option`, written as `null`), never as a NaN.
//!
//! The walk is this module's own serializer: `serde_path_to_error` tracks paths too, but loses
//! them inside an `Option` (it does not follow `serialize_some`), which is where most of the
//! pose stage's numbers are.
//!
//! [`write_pretty`] adds the atomic, durable write of [`crate::fsio`].

use std::fmt;
use std::path::{Path, PathBuf};

use serde::ser::{self, Serialize};

use crate::fsio::{write_atomic, WriteError};

/// A value that could not become JSON, naming the file it was for.
#[derive(Debug, thiserror::Error)]
pub enum JsonError {
    /// A number is NaN or infinite: JSON cannot hold it and `serde_json` would write `null`.
    #[error("{file}: field {field} is {value}, which JSON cannot hold")]
    NonFinite {
        /// The file (or stream) the JSON was for.
        file: PathBuf,
        /// The field's JSON path, e.g. `images[3].world_from_camera.sigma[2]` (`.` for the
        /// value itself).
        field: String,
        /// The number (an `f32` is widened).
        value: f64,
    },
    /// The value's own `Serialize` implementation failed (e.g. a map whose keys are not
    /// strings or numbers).
    #[error("{file}: field {field} cannot be serialised: {problem}")]
    Unserializable {
        /// The file (or stream) the JSON was for.
        file: PathBuf,
        /// The field's JSON path.
        field: String,
        /// What the implementation said.
        problem: String,
    },
    /// `serde_json` refused a value that the check passed.
    #[error("{file}: cannot be written as JSON")]
    Json {
        /// The file (or stream) the JSON was for.
        file: PathBuf,
        /// The serializer's error.
        #[source]
        source: serde_json::Error,
    },
    /// The atomic write failed.
    #[error(transparent)]
    Write(#[from] WriteError),
}

impl JsonError {
    /// The file (or stream) the JSON was for.
    pub fn file(&self) -> &Path {
        match self {
            Self::NonFinite { file, .. }
            | Self::Unserializable { file, .. }
            | Self::Json { file, .. } => file,
            Self::Write(e) => &e.path,
        }
    }

    /// What went wrong, without the file and with its causes: for an error type of the form
    /// `{path}: {problem}` that names the file itself.
    pub fn problem(&self) -> String {
        match self {
            Self::NonFinite { field, value, .. } => {
                format!("field {field} is {value}, which JSON cannot hold")
            }
            Self::Unserializable { field, problem, .. } => {
                format!("field {field} cannot be serialised: {problem}")
            }
            Self::Json { source, .. } => format!("cannot be written as JSON: {source}"),
            Self::Write(e) => crate::error_text(&e.source),
        }
    }
}

/// Checks that every number in `value` is finite, without writing anything. `file` only names
/// the destination in the error.
pub fn check_finite<T: Serialize + ?Sized>(file: &Path, value: &T) -> Result<(), JsonError> {
    let mut checker = Checker::default();
    value.serialize(&mut checker).map_err(|e| {
        let field = path_text(&checker.path);
        match e {
            CheckError::NonFinite(value) => JsonError::NonFinite {
                file: file.to_path_buf(),
                field,
                value,
            },
            CheckError::Custom(problem) => JsonError::Unserializable {
                file: file.to_path_buf(),
                field,
                problem,
            },
        }
    })
}

fn json_error(file: &Path) -> impl FnOnce(serde_json::Error) -> JsonError + '_ {
    |source| JsonError::Json {
        file: file.to_path_buf(),
        source,
    }
}

/// `value` as pretty JSON ending with a newline, after [`check_finite`].
pub fn to_vec_pretty<T: Serialize + ?Sized>(file: &Path, value: &T) -> Result<Vec<u8>, JsonError> {
    check_finite(file, value)?;
    let mut bytes = serde_json::to_vec_pretty(value).map_err(json_error(file))?;
    bytes.push(b'\n');
    Ok(bytes)
}

/// `value` as compact JSON (one line, no newline), after [`check_finite`]: for JSON embedded in
/// another file (a binary file's header).
pub fn to_vec<T: Serialize + ?Sized>(file: &Path, value: &T) -> Result<Vec<u8>, JsonError> {
    check_finite(file, value)?;
    serde_json::to_vec(value).map_err(json_error(file))
}

/// `value` as pretty JSON text (no trailing newline), after [`check_finite`]: for stdout, where
/// `println!` adds the newline.
pub fn to_string_pretty<T: Serialize + ?Sized>(
    file: &Path,
    value: &T,
) -> Result<String, JsonError> {
    check_finite(file, value)?;
    serde_json::to_string_pretty(value).map_err(json_error(file))
}

/// `value` as a [`serde_json::Value`], after [`check_finite`]: for a value carried inside another
/// JSON document (where `serde_json::to_value` would have turned a NaN into `null` unseen).
pub fn to_value<T: Serialize + ?Sized>(
    file: &Path,
    value: &T,
) -> Result<serde_json::Value, JsonError> {
    check_finite(file, value)?;
    serde_json::to_value(value).map_err(json_error(file))
}

/// Writes `value` to `path` as pretty JSON ending with a newline, atomically and durably
/// ([`crate::fsio::write_atomic`]), after [`check_finite`]: nothing is written when a number is
/// not finite, and the old file stays.
pub fn write_pretty<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), JsonError> {
    let bytes = to_vec_pretty(path, value)?;
    write_atomic(path, &bytes)?;
    Ok(())
}

/// What stopped [`Checker`].
#[derive(Debug)]
enum CheckError {
    /// A NaN or infinite number (an `f32` widened).
    NonFinite(f64),
    /// The value's `Serialize` implementation failed.
    Custom(String),
}

impl fmt::Display for CheckError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NonFinite(v) => write!(f, "{v} is not a finite number"),
            Self::Custom(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for CheckError {}

impl ser::Error for CheckError {
    fn custom<M: fmt::Display>(msg: M) -> Self {
        Self::Custom(msg.to_string())
    }
}

/// One step of a JSON path.
#[derive(Debug)]
enum Segment {
    /// A struct field, or an enum variant (JSON writes `{"Variant": ...}`).
    Field(&'static str),
    /// A map key, as JSON writes it.
    Key(String),
    /// An element of a sequence or tuple.
    Index(usize),
}

/// A JSON path: `images[3].world_from_camera.sigma[2]`, `.` for the root.
fn path_text(path: &[Segment]) -> String {
    let mut text = String::new();
    for seg in path {
        match seg {
            Segment::Field(name) => {
                if !text.is_empty() {
                    text.push('.');
                }
                text.push_str(name);
            }
            Segment::Key(key) => {
                if !text.is_empty() {
                    text.push('.');
                }
                text.push_str(key);
            }
            Segment::Index(i) => text.push_str(&format!("[{i}]")),
        }
    }
    if text.is_empty() {
        text.push('.');
    }
    text
}

/// A serializer that writes nothing and fails at the first non-finite number, keeping the path
/// to the value it is in. On an error the path is left as it was at the failure (nothing is
/// popped on the way out), so it names the failing value.
#[derive(Debug, Default)]
struct Checker {
    path: Vec<Segment>,
}

impl Checker {
    /// Checks `value` one step down the path.
    fn child<T: Serialize + ?Sized>(&mut self, seg: Segment, value: &T) -> Checked {
        self.path.push(seg);
        value.serialize(&mut *self)?;
        self.path.pop();
        Ok(())
    }
}

type Checked = Result<(), CheckError>;

/// A struct, sequence, tuple or map being checked: the index of its next element, and the key
/// of the map entry whose value comes next.
#[derive(Debug)]
struct Compound<'a> {
    checker: &'a mut Checker,
    /// Whether an enum variant's name was pushed for it (popped at its end).
    variant: bool,
    next_index: usize,
    key: Option<String>,
}

impl<'a> Compound<'a> {
    fn new(checker: &'a mut Checker) -> Self {
        Self {
            checker,
            variant: false,
            next_index: 0,
            key: None,
        }
    }

    fn of_variant(checker: &'a mut Checker, variant: &'static str) -> Self {
        checker.path.push(Segment::Field(variant));
        Self {
            variant: true,
            ..Self::new(checker)
        }
    }

    fn element<T: Serialize + ?Sized>(&mut self, value: &T) -> Checked {
        let i = self.next_index;
        self.next_index += 1;
        self.checker.child(Segment::Index(i), value)
    }

    fn end(self) -> Checked {
        if self.variant {
            self.checker.path.pop();
        }
        Ok(())
    }
}

/// How JSON writes a map key: a string as itself, anything else (a number, a unit variant) as
/// its JSON text.
fn key_text<T: Serialize + ?Sized>(key: &T) -> String {
    match serde_json::to_value(key) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(v) => v.to_string(),
        Err(_) => "?".to_string(),
    }
}

impl<'a> ser::Serializer for &'a mut Checker {
    type Ok = ();
    type Error = CheckError;
    type SerializeSeq = Compound<'a>;
    type SerializeTuple = Compound<'a>;
    type SerializeTupleStruct = Compound<'a>;
    type SerializeTupleVariant = Compound<'a>;
    type SerializeMap = Compound<'a>;
    type SerializeStruct = Compound<'a>;
    type SerializeStructVariant = Compound<'a>;

    fn serialize_bool(self, _: bool) -> Checked {
        Ok(())
    }
    fn serialize_i8(self, _: i8) -> Checked {
        Ok(())
    }
    fn serialize_i16(self, _: i16) -> Checked {
        Ok(())
    }
    fn serialize_i32(self, _: i32) -> Checked {
        Ok(())
    }
    fn serialize_i64(self, _: i64) -> Checked {
        Ok(())
    }
    fn serialize_i128(self, _: i128) -> Checked {
        Ok(())
    }
    fn serialize_u8(self, _: u8) -> Checked {
        Ok(())
    }
    fn serialize_u16(self, _: u16) -> Checked {
        Ok(())
    }
    fn serialize_u32(self, _: u32) -> Checked {
        Ok(())
    }
    fn serialize_u64(self, _: u64) -> Checked {
        Ok(())
    }
    fn serialize_u128(self, _: u128) -> Checked {
        Ok(())
    }
    fn serialize_f32(self, v: f32) -> Checked {
        self.serialize_f64(f64::from(v))
    }
    fn serialize_f64(self, v: f64) -> Checked {
        if v.is_finite() {
            Ok(())
        } else {
            Err(CheckError::NonFinite(v))
        }
    }
    fn serialize_char(self, _: char) -> Checked {
        Ok(())
    }
    fn serialize_str(self, _: &str) -> Checked {
        Ok(())
    }
    fn serialize_bytes(self, _: &[u8]) -> Checked {
        Ok(())
    }
    fn serialize_none(self) -> Checked {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Checked {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Checked {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Checked {
        Ok(())
    }
    fn serialize_unit_variant(self, _: &'static str, _: u32, _: &'static str) -> Checked {
        Ok(())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Checked {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> Checked {
        self.child(Segment::Field(variant), value)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::new(self))
    }
    fn serialize_tuple(self, _: usize) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::new(self))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::new(self))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::of_variant(self, variant))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::new(self))
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::new(self))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, CheckError> {
        Ok(Compound::of_variant(self, variant))
    }
}

impl ser::SerializeSeq for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Checked {
        self.element(value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

impl ser::SerializeTuple for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Checked {
        self.element(value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

impl ser::SerializeTupleStruct for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Checked {
        self.element(value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

impl ser::SerializeTupleVariant for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Checked {
        self.element(value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

impl ser::SerializeMap for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Checked {
        let text = key_text(key);
        // A key is checked too (a float key must be finite), at its own path.
        self.checker.child(Segment::Key(text.clone()), key)?;
        self.key = Some(text);
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Checked {
        let key = self.key.take().unwrap_or_else(|| "?".to_string());
        self.checker.child(Segment::Key(key), value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

impl ser::SerializeStruct for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, name: &'static str, value: &T) -> Checked {
        self.checker.child(Segment::Field(name), value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

impl ser::SerializeStructVariant for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, name: &'static str, value: &T) -> Checked {
        self.checker.child(Segment::Field(name), value)
    }
    fn end(self) -> Checked {
        Compound::end(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(serde::Serialize)]
    struct Pose {
        sigma: [f64; 3],
        scale: Option<f32>,
    }

    #[derive(serde::Serialize)]
    struct Image {
        name: String,
        world_from_camera: Pose,
    }

    #[derive(serde::Serialize)]
    struct Doc {
        images: Vec<Image>,
        by_name: BTreeMap<String, f64>,
        kind: Kind,
    }

    #[derive(serde::Serialize)]
    enum Kind {
        Fitted { rms: f64 },
        Scale(f64),
    }

    fn doc() -> Doc {
        let image = |i: u32| Image {
            name: format!("im{i}"),
            world_from_camera: Pose {
                sigma: [0.1, 0.2, 0.3],
                scale: Some(1.0),
            },
        };
        Doc {
            images: (0..4).map(image).collect(),
            by_name: BTreeMap::from([("a".to_string(), 1.0)]),
            kind: Kind::Fitted { rms: 0.5 },
        }
    }

    fn refused(d: &Doc) -> (String, f64) {
        match to_vec_pretty(Path::new("out/poses.json"), d) {
            Err(JsonError::NonFinite { file, field, value }) => {
                assert_eq!(file, Path::new("out/poses.json"));
                (field, value)
            }
            other => panic!("expected a non-finite refusal, got {other:?}"),
        }
    }

    #[test]
    fn finite_values_are_written_as_serde_json_writes_them() {
        let d = doc();
        let bytes = to_vec_pretty(Path::new("a.json"), &d).expect("finite");
        let mut want = serde_json::to_vec_pretty(&d).expect("json");
        want.push(b'\n');
        assert_eq!(bytes, want);
        assert_eq!(
            to_vec(Path::new("a.json"), &d).expect("finite"),
            serde_json::to_vec(&d).expect("json")
        );
        assert_eq!(
            to_value(Path::new("a.json"), &d).expect("finite"),
            serde_json::to_value(&d).expect("json")
        );
    }

    #[test]
    fn nan_is_refused_with_the_path_of_its_field() {
        let mut d = doc();
        d.images[3].world_from_camera.sigma[2] = f64::NAN;
        let (field, value) = refused(&d);
        assert_eq!(field, "images[3].world_from_camera.sigma[2]");
        assert!(value.is_nan());
    }

    #[test]
    fn infinities_and_f32_are_refused_too() {
        let mut d = doc();
        d.images[1].world_from_camera.scale = Some(f32::NEG_INFINITY);
        assert_eq!(
            refused(&d),
            (
                "images[1].world_from_camera.scale".into(),
                f64::NEG_INFINITY
            )
        );
        let mut d = doc();
        d.by_name.insert("b".into(), f64::INFINITY);
        assert_eq!(refused(&d), ("by_name.b".into(), f64::INFINITY));
        let mut d = doc();
        d.kind = Kind::Fitted { rms: f64::INFINITY };
        // An enum variant is the key JSON writes for it.
        assert_eq!(refused(&d), ("kind.Fitted.rms".into(), f64::INFINITY));
        let mut d = doc();
        d.kind = Kind::Scale(f64::NAN);
        assert_eq!(refused(&d).0, "kind.Scale");
    }

    #[test]
    fn the_path_goes_through_options_newtypes_tuples_and_number_keys() {
        #[derive(serde::Serialize)]
        struct Cov {
            rms_px: f64,
        }
        #[derive(serde::Serialize)]
        struct Wrapped(Vec<(u32, f64)>);
        #[derive(serde::Serialize)]
        struct Outer {
            world_from_head: Option<Cov>,
            pairs: Option<Wrapped>,
            by_id: BTreeMap<u32, Vec<f32>>,
        }
        let ok = || Outer {
            world_from_head: Some(Cov { rms_px: 0.2 }),
            pairs: Some(Wrapped(vec![(1, 1.0), (2, 2.0)])),
            by_id: BTreeMap::from([(7, vec![1.0, 2.0])]),
        };
        let field = |o: &Outer| match check_finite(Path::new("f.json"), o) {
            Err(JsonError::NonFinite { field, .. }) => field,
            other => panic!("expected a refusal, got {other:?}"),
        };
        assert!(check_finite(Path::new("f.json"), &ok()).is_ok());
        let mut o = ok();
        o.world_from_head = Some(Cov { rms_px: f64::NAN });
        assert_eq!(field(&o), "world_from_head.rms_px");
        let mut o = ok();
        o.pairs = Some(Wrapped(vec![(1, 1.0), (2, f64::NAN)]));
        assert_eq!(field(&o), "pairs[1][1]");
        let mut o = ok();
        o.by_id.insert(9, vec![0.0, 0.0, f32::INFINITY]);
        assert_eq!(field(&o), "by_id.9[2]");
    }

    #[test]
    fn a_bare_number_has_the_root_path() {
        match to_string_pretty(Path::new("stdout"), &f64::NAN) {
            Err(JsonError::NonFinite { field, .. }) => assert_eq!(field, "."),
            other => panic!("expected a refusal, got {other:?}"),
        }
        assert!(check_finite(Path::new("x"), &Option::<f64>::None).is_ok());
    }

    #[test]
    fn the_message_names_file_field_and_value() {
        let mut d = doc();
        d.images[0].world_from_camera.sigma[0] = f64::NAN;
        let err = to_vec_pretty(Path::new("out/poses.json"), &d).expect_err("NaN");
        assert_eq!(
            err.to_string(),
            "out/poses.json: field images[0].world_from_camera.sigma[0] is NaN, \
             which JSON cannot hold"
        );
        assert_eq!(
            err.problem(),
            "field images[0].world_from_camera.sigma[0] is NaN, which JSON cannot hold"
        );
    }

    #[test]
    fn a_refused_value_leaves_the_old_file() {
        let dir = std::env::temp_dir().join(format!("skinbrdf-json-{}", std::process::id()));
        let path = dir.join("poses.json");
        write_pretty(&path, &doc()).expect("first write");
        let before = std::fs::read(&path).expect("read");
        let mut d = doc();
        d.images[2].world_from_camera.sigma[1] = f64::NAN;
        let err = write_pretty(&path, &d).expect_err("NaN");
        assert_eq!(err.file(), path);
        assert_eq!(std::fs::read(&path).expect("read"), before);
        let names: Vec<_> = std::fs::read_dir(&dir)
            .expect("dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names.len(), 1, "no temporary file is left: {names:?}");
        std::fs::remove_dir_all(&dir).expect("clean up");
    }

    #[test]
    fn values_serde_json_refuses_are_errors_naming_the_file() {
        #[derive(serde::Serialize)]
        struct Bad {
            keys: BTreeMap<Vec<u8>, f64>,
        }
        let bad = Bad {
            keys: BTreeMap::from([(vec![1u8], 1.0)]),
        };
        // The check writes nothing and so accepts any key; serde_json refuses a sequence key.
        let err = to_vec_pretty(Path::new("k.json"), &bad).expect_err("a sequence key");
        assert!(matches!(err, JsonError::Json { .. }), "{err:?}");
        assert_eq!(err.file(), Path::new("k.json"));
    }
}
