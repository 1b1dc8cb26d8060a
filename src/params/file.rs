//! Parameter files in the three formats ground stations write, detected automatically:
//!
//! - MAVProxy: `NAME VALUE` separated by blanks, `#` starts a comment;
//! - Mission Planner: `NAME,VALUE`, `#` comments;
//! - QGroundControl: tab-separated `SYS COMP NAME VALUE TYPE`, `#` comments.
//!
//! Values are written as the shortest decimal that reads back to the same float32 (Rust's
//! `Display` for `f32`), so every finite value round-trips bit for bit; MAVProxy's `%f` keeps
//! six decimals and loses small gains. A file is either wholly usable or refused with the first
//! bad line's number: wrong column count, a number that does not parse, NaN, infinity, a name a
//! vehicle cannot carry, a duplicate name.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::{MavParamType, Param, ParamSet, valid_name};
use vtol_link::text_file::{self, TextFileError};
use vtol_link::{ComponentId, SystemId};

/// A parameter file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// `NAME VALUE` (MAVProxy `param save`).
    Mavproxy,
    /// `NAME,VALUE` (Mission Planner).
    Missionplanner,
    /// `SYS<TAB>COMP<TAB>NAME<TAB>VALUE<TAB>TYPE` (QGroundControl).
    Qgc,
}

/// A file that cannot be used. Nothing is sent to a vehicle from a file with an error.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// Reading or writing failed, or a line is wrong (the same errors as the twin's
    /// parameter and mission files).
    #[error(transparent)]
    File(#[from] TextFileError),
    /// The file holds no parameter.
    #[error("{path}: no parameters in the file")]
    Empty {
        /// The file.
        path: PathBuf,
    },
}

/// A parsed file: the values, the line of each name (for later errors) and the format found.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamFile {
    /// The values. Files without a type column carry REAL32; the vehicle's type decides.
    pub params: ParamSet,
    /// 1-based line of each parameter.
    pub lines: BTreeMap<String, usize>,
    /// The detected format.
    pub format: Format,
    /// Whether the file gave the types (QGroundControl).
    pub typed: bool,
}

impl ParamFile {
    /// Reads and parses a file.
    ///
    /// # Errors
    /// [`FileError`] naming the file and line.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = text_file::read_text(path)?;
        Self::parse(&text, path)
    }

    /// Parses file text; `path` only names the file in errors.
    ///
    /// # Errors
    /// [`TextFileError::Line`] for the first bad line, [`FileError::Empty`] for a file without
    /// values.
    pub fn parse(text: &str, path: &Path) -> Result<Self, FileError> {
        let err =
            |line: usize, reason: String| FileError::from(TextFileError::line(path, line, reason));
        let mut format = None;
        let mut params = ParamSet::new();
        let mut lines = BTreeMap::new();
        for (i, raw) in text.lines().enumerate() {
            let n = i + 1;
            let content = raw.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            let f = *format.get_or_insert_with(|| detect(content));
            let (name, value_text, ty) = split_line(f, content).map_err(|r| err(n, r))?;
            if !valid_name(name) {
                return Err(err(
                    n,
                    format!(
                        "'{name}' is not a parameter name (1-16 characters, no blanks, commas or #)"
                    ),
                ));
            }
            let value: f32 = value_text
                .parse()
                .map_err(|_| err(n, format!("{name}: '{value_text}' is not a number")))?;
            if !value.is_finite() {
                return Err(err(n, format!("{name}: value {value_text} is not finite")));
            }
            if let Some(first) = lines.get(name) {
                return Err(err(
                    n,
                    format!("{name} appears twice (first on line {first})"),
                ));
            }
            lines.insert(name.to_owned(), n);
            params.insert(name.to_owned(), Param { value, ty });
        }
        let Some(format) = format else {
            return Err(FileError::Empty {
                path: path.to_owned(),
            });
        };
        Ok(Self {
            params,
            lines,
            format,
            typed: format == Format::Qgc,
        })
    }
}

fn detect(first: &str) -> Format {
    if first.contains('\t') && first.split('\t').count() >= 5 {
        Format::Qgc
    } else if first.contains(',') {
        Format::Missionplanner
    } else {
        Format::Mavproxy
    }
}

fn split_line(f: Format, content: &str) -> Result<(&str, &str, MavParamType), String> {
    match f {
        Format::Mavproxy => {
            let cols: Vec<&str> = content.split_whitespace().collect();
            match cols.as_slice() {
                [name, value] => Ok((name, value, MavParamType::MAV_PARAM_TYPE_REAL32)),
                _ => Err(format!(
                    "expected 'NAME VALUE' (MAVProxy format, as the first line), found {} column(s)",
                    cols.len()
                )),
            }
        }
        Format::Missionplanner => {
            let cols: Vec<&str> = content.split(',').map(str::trim).collect();
            match cols.as_slice() {
                [name, value] => Ok((name, value, MavParamType::MAV_PARAM_TYPE_REAL32)),
                _ => Err(format!(
                    "expected 'NAME,VALUE' (Mission Planner format, as the first line), found {} column(s)",
                    cols.len()
                )),
            }
        }
        Format::Qgc => {
            let cols: Vec<&str> = content.split('\t').map(str::trim).collect();
            let [sys, comp, name, value, ty] = cols.as_slice() else {
                return Err(format!(
                    "expected 'SYS<TAB>COMP<TAB>NAME<TAB>VALUE<TAB>TYPE' (QGroundControl format, as the first line), found {} column(s)",
                    cols.len()
                ));
            };
            for (what, v) in [("system id", sys), ("component id", comp)] {
                if v.parse::<u8>().is_err() {
                    return Err(format!("{what} '{v}' is not 0-255"));
                }
            }
            let ty = ty
                .parse::<u32>()
                .ok()
                .and_then(param_type_from_number)
                .ok_or_else(|| format!("{name}: '{ty}' is not a MAV_PARAM_TYPE (1-10)"))?;
            Ok((name, value, ty))
        }
    }
}

/// `MAV_PARAM_TYPE` from its number.
#[must_use]
pub fn param_type_from_number(n: u32) -> Option<MavParamType> {
    num_traits::FromPrimitive::from_u32(n)
}

/// The shortest decimal that reads back to the same float32 (`-0` keeps its sign).
#[must_use]
pub fn format_value(v: f32) -> String {
    v.to_string()
}

/// A parameter set as file text. `vehicle` is (system, component) for the QGroundControl
/// columns.
#[must_use]
pub fn render(params: &ParamSet, format: Format, vehicle: (SystemId, ComponentId)) -> String {
    let mut out = String::new();
    match format {
        Format::Mavproxy => {
            for (name, p) in params {
                let _ = writeln!(out, "{name:<16} {}", format_value(p.value));
            }
        }
        Format::Missionplanner => {
            for (name, p) in params {
                let _ = writeln!(out, "{name},{}", format_value(p.value));
            }
        }
        Format::Qgc => {
            let (sys, comp) = vehicle;
            let _ = writeln!(out, "# Onboard parameters for Vehicle {sys}");
            out.push_str("#\n# Vehicle-Id Component-Id Name Value Type\n");
            for (name, p) in params {
                let _ = writeln!(
                    out,
                    "{sys}\t{comp}\t{name}\t{}\t{}",
                    format_value(p.value),
                    p.ty as u32
                );
            }
        }
    }
    out
}

/// Writes a file atomically (a temporary beside it, flushed, then a rename), so an interrupted
/// save never leaves half a file.
///
/// # Errors
/// [`TextFileError::Io`].
pub fn save(
    path: &Path,
    params: &ParamSet,
    format: Format,
    vehicle: (SystemId, ComponentId),
) -> Result<(), FileError> {
    Ok(text_file::write_text(
        path,
        &render(params, format, vehicle),
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn parse(text: &str) -> Result<ParamFile, FileError> {
        ParamFile::parse(text, Path::new("t.param"))
    }

    fn line_of(e: FileError) -> (usize, String) {
        match e {
            FileError::File(TextFileError::Line { line, reason, .. }) => (line, reason),
            other => panic!("expected a line error, got {other}"),
        }
    }

    #[test]
    fn each_format_is_detected() {
        let mp = parse("# gains\nLAT_SAT_A 1.2  # comment\nALT_KP\t5\n").expect("mavproxy");
        assert_eq!(mp.format, Format::Mavproxy);
        assert_eq!(mp.params["ALT_KP"].value, 5.0);
        let mpl = parse("LAT_SAT_A,1.2\nALT_KP,5\n").expect("mission planner");
        assert_eq!(mpl.format, Format::Missionplanner);
        let q = parse("# x\n1\t1\tLAT_SAT_A\t1.2\t9\n1\t1\tFS_GCS_ENABL\t1\t2\n").expect("qgc");
        assert_eq!(q.format, Format::Qgc);
        assert_eq!(
            q.params["FS_GCS_ENABL"].ty,
            MavParamType::MAV_PARAM_TYPE_INT8
        );
        assert_eq!(q.lines["FS_GCS_ENABL"], 3);
    }

    #[test]
    fn bad_files_name_the_line() {
        let cases = [
            ("A 1\nB 2 3\n", 2, "column"),
            ("A 1\nB nan\n", 2, "not finite"),
            ("A 1\n\nB inf\n", 3, "not finite"),
            ("A 1\nB x\n", 2, "not a number"),
            ("A 1\nA 2\n", 2, "twice"),
            ("A,1\nB 2\n", 2, "column"),
            ("TOO_LONG_NAME_XXXX 1\n", 1, "not a parameter name"),
            ("1\t1\tA\t1\t99\n", 1, "MAV_PARAM_TYPE"),
            ("1\t1\tA\t1\t9\n1\t1\tB\t2\n", 2, "column"),
        ];
        for (text, line, what) in cases {
            let (l, reason) = line_of(parse(text).expect_err(text));
            assert_eq!(l, line, "{text:?}: {reason}");
            assert!(reason.contains(what), "{text:?}: {reason}");
        }
        assert!(matches!(parse("# only\n\n"), Err(FileError::Empty { .. })));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// Every finite float32 survives every format bit for bit.
        #[test]
        fn every_finite_f32_round_trips(bits in any::<u32>(), fmt in 0usize..3) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            let format = [Format::Mavproxy, Format::Missionplanner, Format::Qgc][fmt];
            let mut set = ParamSet::new();
            set.insert("LAT_SAT_A".into(), Param { value: v, ty: MavParamType::MAV_PARAM_TYPE_REAL32 });
            set.insert("SR0_EXTRA1".into(), Param { value: -1.0, ty: MavParamType::MAV_PARAM_TYPE_INT16 });
            let text = render(&set, format, (SystemId(1), ComponentId(1)));
            let back = parse(&text).expect("own output parses");
            prop_assert_eq!(back.format, format);
            prop_assert_eq!(back.params["LAT_SAT_A"].value.to_bits(), bits);
            if format == Format::Qgc {
                prop_assert_eq!(&back.params, &set);
            }
        }
    }

    #[test]
    fn shortest_decimal() {
        assert_eq!(format_value(0.1), "0.1");
        assert_eq!(format_value(1.2), "1.2");
        assert_eq!(format_value(5.0), "5");
        assert_eq!(format_value(-0.0), "-0");
    }
}

#[cfg(test)]
mod shipped_gains {
    use std::path::Path;

    use super::ParamFile;

    /// `config/gains.param` parses and holds exactly the twin's default gains (stored as float32).
    #[test]
    fn config_gains_are_the_twins_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/gains.param");
        let f = ParamFile::load(&path).expect("config/gains.param parses");
        assert_eq!(f.params.len(), 12);
        for (name, p) in &f.params {
            let i = firmware_sim::nav::params::Params::index_of(name).expect("a twin parameter");
            let d = firmware_sim::nav::params::TABLE[i];
            assert_eq!(p.value, d.default as f32, "{name}");
        }
    }
}
