//! Stage options: a small typed schema, and the validated values a stage receives.
//!
//! Options travel as JSON (they cross the plugin boundary), so the schema is JSON too.
//! The runner checks user options against the schema before a stage runs, so stages can
//! read typed values without re-validating, and a typo in a pipeline file is an error
//! rather than a silently ignored key.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::stage::StageError;

/// A colour option: `black`, `white` or `R,G,B` in 0..1; the error names `option`.
pub fn parse_colour(option: &str, text: &str) -> Result<[f32; 3], StageError> {
    match text.trim() {
        "black" => return Ok([0.0; 3]),
        "white" => return Ok([1.0; 3]),
        _ => {}
    }
    let bad = || {
        StageError::Options(format!(
            "option '{option}': expected black, white or three numbers in 0..1 like \
             \"0.5,0.5,0.5\", got {text:?}"
        ))
    };
    let parts: Vec<f32> = text
        .split(',')
        .map(|s| s.trim().parse::<f32>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match parts[..] {
        [r, g, b] if parts.iter().all(|v| (0.0..=1.0).contains(v)) => Ok([r, g, b]),
        _ => Err(bad()),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OptionKind {
    Bool,
    Int,
    Float,
    String,
    Path,
}

impl OptionKind {
    fn accepts(self, v: &Value) -> bool {
        match self {
            Self::Bool => v.is_boolean(),
            Self::Int => v.is_i64() || v.is_u64(),
            Self::Float => v.is_number(),
            Self::String | Self::Path => v.is_string(),
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Bool => "bool",
            Self::Int => "int",
            Self::Float => "float",
            Self::String => "string",
            Self::Path => "path",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OptionSpec {
    pub name: String,
    pub kind: OptionKind,
    /// `None` means the option is required.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub default: Option<Value>,
    #[serde(default)]
    pub help: String,
    /// Smallest accepted value of a number (inclusive).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest accepted value of a number (inclusive).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// The texts a string option takes; empty: any. A plugin built before the field sends
    /// none, which reads as any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub choices: Vec<String>,
}

impl OptionSpec {
    pub fn new(name: &str, kind: OptionKind, default: Option<Value>, help: &str) -> Self {
        Self {
            name: name.to_owned(),
            kind,
            default,
            help: help.to_owned(),
            min: None,
            max: None,
            choices: Vec::new(),
        }
    }

    /// A text other than `choices` is refused before any stage of a run starts (a pipeline's
    /// last stage included), not when its stage reads it.
    pub fn one_of(mut self, choices: &[&str]) -> Self {
        self.choices = choices.iter().map(|c| (*c).to_owned()).collect();
        self
    }

    /// Why `v` is not one of `choices`, if it is not.
    fn not_a_choice(&self, v: &Value) -> Option<String> {
        let text = v.as_str()?;
        let (last, rest) = self.choices.split_last()?;
        (!self.choices.iter().any(|c| c == text)).then(|| {
            let listed = if rest.is_empty() {
                last.clone()
            } else {
                format!("{} or {last}", rest.join(", "))
            };
            format!("expected {listed}")
        })
    }

    /// Numbers below `min` are refused before the stage runs.
    pub fn at_least(mut self, min: f64) -> Self {
        self.min = Some(min);
        self
    }

    /// Numbers outside `min..=max` are refused before the stage runs.
    pub fn between(mut self, min: f64, max: f64) -> Self {
        self.min = Some(min);
        self.max = Some(max);
        self
    }

    /// Why `v` (already of the right kind) is out of range, if it is.
    fn out_of_range(&self, v: &Value) -> Option<String> {
        let x = v.as_f64()?;
        let low = self.min.is_some_and(|m| x < m);
        let high = self.max.is_some_and(|m| x > m);
        (low || high).then(|| match (self.min, self.max) {
            (Some(a), Some(b)) => format!("expected a number from {a} to {b}"),
            (Some(a), None) => format!("expected a number of at least {a}"),
            (None, Some(b)) => format!("expected a number of at most {b}"),
            (None, None) => unreachable!("a range check without bounds"),
        })
    }

    pub fn int(name: &str, default: i64, help: &str) -> Self {
        Self::new(name, OptionKind::Int, Some(default.into()), help)
    }

    pub fn float(name: &str, default: f64, help: &str) -> Self {
        Self::new(name, OptionKind::Float, Some(default.into()), help)
    }

    pub fn bool(name: &str, default: bool, help: &str) -> Self {
        Self::new(name, OptionKind::Bool, Some(default.into()), help)
    }

    pub fn string(name: &str, default: &str, help: &str) -> Self {
        Self::new(name, OptionKind::String, Some(default.into()), help)
    }

    /// An option without a default: the stage cannot run without it.
    pub fn required(name: &str, kind: OptionKind, help: &str) -> Self {
        Self::new(name, kind, None, help)
    }

    /// An option that may be absent, with no default value.
    pub fn optional(name: &str, kind: OptionKind, help: &str) -> Self {
        Self::new(name, kind, Some(Value::Null), help)
    }
}

/// Option values checked against a stage's schema, with defaults filled in.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Options(pub Map<String, Value>);

impl Options {
    /// Checks `given` against `specs`: unknown names, wrong types and missing required
    /// options are errors; absent options take their defaults.
    pub fn validate(
        stage: &str,
        specs: &[OptionSpec],
        given: &Map<String, Value>,
    ) -> Result<Self, StageError> {
        for key in given.keys() {
            if !specs.iter().any(|s| &s.name == key) {
                let known: Vec<&str> = specs.iter().map(|s| s.name.as_str()).collect();
                return Err(StageError::Options(format!(
                    "stage '{stage}' has no option '{key}' (it has: {})",
                    if known.is_empty() {
                        "none".to_owned()
                    } else {
                        known.join(", ")
                    }
                )));
            }
        }
        let mut out = Map::new();
        for spec in specs {
            match given.get(&spec.name).filter(|v| !v.is_null()) {
                // A text option whose text can be a number (a distance or "from:VIEW") takes a
                // bare JSON number too, as its text.
                Some(v) if spec.kind == OptionKind::String && v.is_number() => {
                    let text = Value::String(v.to_string());
                    if let Some(why) = spec.not_a_choice(&text) {
                        return Err(StageError::Options(format!(
                            "stage '{stage}' option '{}': {why}, got {v}",
                            spec.name
                        )));
                    }
                    out.insert(spec.name.clone(), text);
                }
                Some(v) if spec.kind.accepts(v) => {
                    if let Some(why) = spec.out_of_range(v).or_else(|| spec.not_a_choice(v)) {
                        return Err(StageError::Options(format!(
                            "stage '{stage}' option '{}': {why}, got {v}",
                            spec.name
                        )));
                    }
                    out.insert(spec.name.clone(), v.clone());
                }
                Some(v) => {
                    return Err(StageError::Options(format!(
                        "stage '{stage}' option '{}': expected {}, got {v}",
                        spec.name,
                        spec.kind.as_str()
                    )));
                }
                None => match &spec.default {
                    Some(d) => {
                        out.insert(spec.name.clone(), d.clone());
                    }
                    None => {
                        return Err(StageError::Options(format!(
                            "stage '{stage}' needs option '{}' ({})",
                            spec.name, spec.help
                        )));
                    }
                },
            }
        }
        Ok(Self(out))
    }

    pub fn get(&self, name: &str) -> Option<&Value> {
        self.0.get(name).filter(|v| !v.is_null())
    }

    pub fn get_bool(&self, name: &str) -> Option<bool> {
        self.get(name).and_then(Value::as_bool)
    }

    pub fn get_i64(&self, name: &str) -> Option<i64> {
        self.get(name).and_then(Value::as_i64)
    }

    pub fn get_u64(&self, name: &str) -> Option<u64> {
        self.get(name).and_then(Value::as_u64)
    }

    pub fn get_f64(&self, name: &str) -> Option<f64> {
        self.get(name).and_then(Value::as_f64)
    }

    pub fn get_str(&self, name: &str) -> Option<&str> {
        self.get(name).and_then(Value::as_str)
    }

    pub fn get_path(&self, name: &str) -> Option<PathBuf> {
        self.get_str(name).map(PathBuf::from)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn specs() -> Vec<OptionSpec> {
        vec![
            OptionSpec::int("points", 200_000, "extra points"),
            OptionSpec::required("gt", OptionKind::Path, "ground truth dir"),
            OptionSpec::optional("model", OptionKind::Int, "sparse model index"),
        ]
    }

    fn map(v: Value) -> Map<String, Value> {
        v.as_object().cloned().unwrap_or_default()
    }

    #[test]
    fn fills_defaults_and_keeps_given() {
        let o = Options::validate("s", &specs(), &map(json!({"gt": "/x"}))).expect("valid");
        assert_eq!(o.get_u64("points"), Some(200_000));
        assert_eq!(o.get_path("gt"), Some(PathBuf::from("/x")));
        assert_eq!(o.get_i64("model"), None);
    }

    #[test]
    fn rejects_unknown_wrong_type_and_missing() {
        let e = Options::validate("s", &specs(), &map(json!({"gt": "/x", "pointz": 1})));
        assert!(e.unwrap_err().to_string().contains("no option 'pointz'"));
        let e = Options::validate("s", &specs(), &map(json!({"gt": "/x", "points": "many"})));
        assert!(e.unwrap_err().to_string().contains("expected int"));
        let e = Options::validate("s", &specs(), &map(json!({})));
        assert!(e.unwrap_err().to_string().contains("needs option 'gt'"));
    }

    #[test]
    fn numbers_outside_their_range_are_refused() {
        let s = vec![
            OptionSpec::float("threshold", 0.5, "").between(0.0, 1.0),
            OptionSpec::int("points", 10, "").at_least(1.0),
        ];
        let ok = Options::validate("s", &s, &map(json!({"threshold": 1, "points": 1})));
        assert!(ok.is_ok());
        let e = Options::validate("s", &s, &map(json!({"threshold": 1.5}))).unwrap_err();
        assert!(
            e.to_string()
                .contains("'threshold': expected a number from 0 to 1, got 1.5"),
            "{e}"
        );
        let e = Options::validate("s", &s, &map(json!({"points": 0}))).unwrap_err();
        assert!(e.to_string().contains("at least 1, got 0"), "{e}");
        // Defaults are the stage's own and are not re-checked.
        let wide = vec![OptionSpec::int("n", 0, "").at_least(1.0)];
        assert!(Options::validate("s", &wide, &map(json!({}))).is_ok());
    }

    #[test]
    fn texts_outside_their_choices_are_refused() {
        let s = vec![OptionSpec::string("format", "ply", "").one_of(&["ply", "glb", "spz"])];
        assert!(Options::validate("s", &s, &map(json!({"format": "glb"}))).is_ok());
        let e = Options::validate("s", &s, &map(json!({"format": 3}))).unwrap_err();
        assert!(
            e.to_string().contains("expected ply, glb or spz, got 3"),
            "{e}"
        );
        let e = Options::validate("s", &s, &map(json!({"format": "obj"}))).unwrap_err();
        assert!(
            e.to_string()
                .contains("'format': expected ply, glb or spz, got \"obj\""),
            "{e}"
        );
        // A plugin's table from before the field reads as any text.
        let old: OptionSpec =
            serde_json::from_value(json!({"name": "f", "kind": "string", "default": "x"}))
                .expect("spec");
        assert!(Options::validate("s", &[old], &map(json!({"f": "anything"}))).is_ok());
    }

    #[test]
    fn int_is_accepted_where_float_is_expected() {
        let s = vec![OptionSpec::float("scale", 1.0, "")];
        let o = Options::validate("s", &s, &map(json!({"scale": 2}))).expect("valid");
        assert_eq!(o.get_f64("scale"), Some(2.0));
    }

    #[test]
    fn colours_parse_by_name_or_numbers_and_say_what_is_expected() {
        assert_eq!(parse_colour("background", "white").unwrap(), [1.0; 3]);
        assert_eq!(parse_colour("background", "black").unwrap(), [0.0; 3]);
        assert_eq!(
            parse_colour("background", " 0.5, 0, 1").unwrap(),
            [0.5, 0.0, 1.0]
        );
        for bad in ["grey", "1,1", "0,0,2", "a,b,c", ""] {
            let e = parse_colour("background", bad).unwrap_err().to_string();
            assert!(
                e.contains("'background'") && e.contains("black, white"),
                "{bad}: {e}"
            );
        }
    }
}
