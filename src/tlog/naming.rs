//! Where a new log goes: a file named after its start time (UTC), never one that exists.

use super::{TlogError, TlogWriter};
use std::io::{self};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

pub(super) fn is_regular_file(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| m.is_file())
}

/// How many suffixed names are tried before giving up on a directory.
pub(super) const MAX_NAME_TRIES: u32 = 1000;

/// Creates the first free name of `<start time>.tlog`, `<start time>-2.tlog`, … in `dir`.
pub(super) fn create_unique(dir: &Path, t: SystemTime) -> Result<(PathBuf, TlogWriter), TlogError> {
    std::fs::create_dir_all(dir).map_err(|source| TlogError::Create {
        path: dir.to_owned(),
        source,
    })?;
    let base = log_file_name(t);
    let stem = base.trim_end_matches(".tlog");
    let mut last_err = None;
    for n in 1..=MAX_NAME_TRIES {
        let name = if n == 1 {
            base.clone()
        } else {
            format!("{stem}-{n}.tlog")
        };
        let path = dir.join(name);
        match TlogWriter::create(&path) {
            Ok(w) => return Ok((path, w)),
            Err(TlogError::Create { source, .. })
                if source.kind() == io::ErrorKind::AlreadyExists =>
            {
                last_err = Some(source);
            }
            Err(e) => return Err(e),
        }
    }
    Err(TlogError::Create {
        path: dir.join(base),
        source: last_err.unwrap_or_else(|| io::Error::other("no free log name")),
    })
}

/// `YYYY-MM-DD_HH-MM-SS.tlog` (UTC) for a start time.
#[must_use]
pub fn log_file_name(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(i64::try_from(days).unwrap_or(0));
    format!(
        "{y:04}-{m:02}-{d:02}_{:02}-{:02}-{:02}.tlog",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

/// Gregorian date from days since 1970-01-01 (H. Hinnant's algorithm).
pub(super) fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = u32::try_from(doy - (153 * mp + 2) / 5 + 1).unwrap_or(1);
    let m = u32::try_from(if mp < 10 { mp + 3 } else { mp - 9 }).unwrap_or(1);
    (era * 400 + yoe + i64::from(m <= 2), m, d)
}
