//! The transactional upload: which order to write a set of changes in, and the state machine
//! that applies them, verifies them by read-back and, on any failure, restores every value it
//! changed. Pure: the client's async shell performs the writes and reads it asks for.
//!
//! Why the order matters: the twin refuses a write that leaves its saturation levels breaking
//! a > b + c + d, b > c + d, c > d > 0 (the hypotheses of the controller's stability proof), so
//! lowering all four levels works only from d up and raising them only from a down. The
//! [`Rules`] model predicts what the vehicle accepts and the planner searches an order in which
//! every intermediate set passes. The vehicle stays the judge: when it refuses a write the
//! transaction goes on with the rest and retries the refused ones after any progress, until no
//! progress is possible; then it rolls back.

use std::collections::BTreeMap;

use super::{Change, ParamSet, same_value};

/// A model of what the vehicle accepts, used only to order writes. `Sync`, so a push can run
/// as a task on the multi-threaded runtime (the terminal UI spawns its requests).
pub trait Rules: Sync {
    /// Why the vehicle would refuse setting `name` to `value` when it holds `state`, or `None`
    /// when it would accept (or the model does not know).
    fn refusal(&self, state: &ParamSet, name: &str, value: f32) -> Option<String>;
}

/// The twin's own validation (`firmware_sim::nav::params`): the same code path the vehicle runs.
/// Names the twin does not have are accepted by the model (a different vehicle decides).
#[derive(Debug, Clone, Copy, Default)]
pub struct TwinRules;

impl Rules for TwinRules {
    fn refusal(&self, state: &ParamSet, name: &str, value: f32) -> Option<String> {
        use firmware_sim::nav::params::Params;
        Params::index_of(name)?;
        let mut table = Params::new();
        for (n, p) in state {
            if Params::index_of(n).is_some() {
                // Values the vehicle holds are accepted as they are (range only, no
                // cross-checks): the state is the vehicle's, right or wrong.
                let _ = table.set_internal(n, decimal(p.value));
            }
        }
        table.set(name, decimal(value)).err().map(|e| e.to_string())
    }
}

/// A float32 as the f64 of its shortest decimal: 1.2f32 is 1.2, not 1.2000000476837158, in
/// what the rules check and in the reasons they give.
fn decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or_else(|_| f64::from(v))
}

/// An order of `changes` in which, by `rules`, every intermediate set is acceptable: a depth-
/// first search that tries the changes in their given order first (so a set that needs no
/// particular order is written as listed). When no full order exists, the longest acceptable
/// prefix is followed by the rest in the given order, and the vehicle will refuse what it
/// refuses. Small sets only: the search is bounded to a few thousand steps.
#[must_use]
pub fn order_writes(current: &ParamSet, changes: &[Change], rules: &dyn Rules) -> Vec<Change> {
    let mut best: Vec<usize> = Vec::new();
    let mut path = Vec::new();
    let mut used = vec![false; changes.len()];
    let mut state = current.clone();
    let mut budget = 20_000usize;
    search(
        changes,
        rules,
        &mut state,
        &mut used,
        &mut path,
        &mut best,
        &mut budget,
    );
    let mut order: Vec<Change> = best.iter().map(|&i| changes[i].clone()).collect();
    for (i, c) in changes.iter().enumerate() {
        if !best.contains(&i) {
            order.push(c.clone());
        }
    }
    order
}

fn search(
    changes: &[Change],
    rules: &dyn Rules,
    state: &mut ParamSet,
    used: &mut [bool],
    path: &mut Vec<usize>,
    best: &mut Vec<usize>,
    budget: &mut usize,
) -> bool {
    if path.len() > best.len() {
        best.clone_from(path);
    }
    if path.len() == changes.len() {
        return true;
    }
    for i in 0..changes.len() {
        if used[i] || *budget == 0 {
            continue;
        }
        *budget -= 1;
        let c = &changes[i];
        if rules.refusal(state, &c.name, c.new).is_some() {
            continue;
        }
        let old = state.get(&c.name).copied();
        if let Some(p) = state.get_mut(&c.name) {
            p.value = c.new;
        }
        used[i] = true;
        path.push(i);
        if search(changes, rules, state, used, path, best, budget) {
            return true;
        }
        path.pop();
        used[i] = false;
        if let (Some(old), Some(p)) = (old, state.get_mut(&c.name)) {
            *p = old;
        }
    }
    false
}

/// What happened to one parameter in a push.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamOutcome {
    /// Written and verified by read-back: the vehicle holds `new`.
    Written {
        /// Value before.
        old: f32,
        /// Value now.
        new: f32,
    },
    /// The vehicle refused the write; it still holds `old`.
    Refused {
        /// Value it holds.
        old: f32,
        /// The vehicle's reason.
        reason: String,
    },
    /// Not written because the transaction failed first; still `old`.
    NotWritten {
        /// Value it holds.
        old: f32,
    },
    /// Written, then restored to `old` (verified) because the transaction failed.
    RolledBack {
        /// Value restored.
        old: f32,
        /// Value that had been written.
        written: f32,
    },
    /// Written, and the restore failed: the vehicle holds `holds` (None: unknown).
    RollbackFailed {
        /// Value before the push.
        old: f32,
        /// What the vehicle holds, when a read-back answered.
        holds: Option<f32>,
        /// Why the restore failed.
        reason: String,
    },
}

/// How a push ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PushResult {
    /// Every change is on the vehicle, verified.
    Applied,
    /// The push failed and every changed value was restored: the vehicle is as before.
    RolledBack {
        /// Why the push failed.
        cause: String,
    },
    /// The push failed and some values could not be restored.
    RollbackIncomplete {
        /// Why the push failed.
        cause: String,
    },
}

/// The per-parameter report of a push.
#[derive(Debug, Clone, PartialEq)]
pub struct PushReport {
    /// How it ended.
    pub result: PushResult,
    /// One entry per parameter that differed, in name order.
    pub outcomes: BTreeMap<String, ParamOutcome>,
    /// Parameters the vehicle now holds at a new value (0 unless `Applied`).
    pub changed: usize,
}

/// Why one write or read did not confirm.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StepError {
    /// The vehicle said no (PARAM_ERROR, or an echo of another value); nothing changed.
    Refused(String),
    /// No answer: the outcome is unknown.
    Lost(String),
}

/// The next thing the transaction needs done.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Write `value` to `name` and report with [`Transaction::written`].
    Write {
        /// Parameter id.
        name: String,
        /// Value to write.
        value: f32,
    },
    /// Read `name` back and report with [`Transaction::read`].
    Read {
        /// Parameter id.
        name: String,
    },
    /// Finished.
    Done(PushReport),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Apply,
    Verify,
    Rollback,
    /// Reading what a parameter whose restore failed holds.
    Inspect,
    Finished,
}

/// The push as a state machine: call [`Transaction::next_step`] for a step, perform it, report the
/// result, repeat until [`Step::Done`].
#[derive(Debug, Clone)]
pub struct Transaction {
    phase: Phase,
    /// Changes not yet accepted, in the planned order.
    pending: Vec<Change>,
    /// Index in `pending` of the next write of this pass.
    cursor: usize,
    progress_this_pass: bool,
    /// Accepted writes, in the order they happened (rollback runs it backwards).
    applied: Vec<Change>,
    /// Writes whose outcome is unknown (no answer): restored like applied ones.
    uncertain: Vec<Change>,
    to_verify: Vec<Change>,
    to_restore: Vec<Change>,
    to_inspect: Vec<String>,
    outcomes: BTreeMap<String, ParamOutcome>,
    refusals: BTreeMap<String, String>,
    cause: Option<String>,
    rollback_failed: bool,
    in_flight: Option<Change>,
}

impl Transaction {
    /// A transaction for `changes`, already ordered (see [`order_writes`]).
    #[must_use]
    pub fn new(changes: Vec<Change>) -> Self {
        let outcomes = changes
            .iter()
            .map(|c| (c.name.clone(), ParamOutcome::NotWritten { old: c.old }))
            .collect();
        Self {
            phase: if changes.is_empty() {
                Phase::Verify
            } else {
                Phase::Apply
            },
            pending: changes,
            cursor: 0,
            progress_this_pass: false,
            applied: Vec::new(),
            uncertain: Vec::new(),
            to_verify: Vec::new(),
            to_restore: Vec::new(),
            to_inspect: Vec::new(),
            outcomes,
            refusals: BTreeMap::new(),
            cause: None,
            rollback_failed: false,
            in_flight: None,
        }
    }

    /// The next step.
    // Long: the transactional upload's state machine, one arm per phase (apply, verify, roll back,
    // inspect), each saying what follows it; kept in one match so every transition is seen
    // together.
    pub fn next_step(&mut self) -> Step {
        loop {
            match self.phase {
                Phase::Apply => {
                    if self.pending.is_empty() {
                        self.to_verify = self.applied.clone();
                        self.phase = Phase::Verify;
                        continue;
                    }
                    if self.cursor >= self.pending.len() {
                        if self.progress_this_pass {
                            self.cursor = 0;
                            self.progress_this_pass = false;
                            continue;
                        }
                        let first = &self.pending[0].name;
                        let reason = self.refusals.get(first).cloned().unwrap_or_default();
                        self.fail(format!("{first} refused: {reason}"));
                        continue;
                    }
                    let c = self.pending[self.cursor].clone();
                    self.in_flight = Some(c.clone());
                    return Step::Write {
                        name: c.name,
                        value: c.new,
                    };
                }
                Phase::Verify => {
                    if let Some(c) = self.to_verify.last().cloned() {
                        self.in_flight = Some(c.clone());
                        return Step::Read { name: c.name };
                    }
                    self.phase = Phase::Finished;
                    let changed = self.applied.len();
                    for c in &self.applied {
                        self.outcomes.insert(
                            c.name.clone(),
                            ParamOutcome::Written {
                                old: c.old,
                                new: c.new,
                            },
                        );
                    }
                    return Step::Done(PushReport {
                        result: PushResult::Applied,
                        outcomes: self.outcomes.clone(),
                        changed,
                    });
                }
                Phase::Rollback => {
                    if let Some(c) = self.to_restore.last().cloned() {
                        self.in_flight = Some(c.clone());
                        return Step::Write {
                            name: c.name,
                            value: c.old,
                        };
                    }
                    self.phase = Phase::Inspect;
                }
                Phase::Inspect => {
                    if let Some(name) = self.to_inspect.last().cloned() {
                        return Step::Read { name };
                    }
                    self.phase = Phase::Finished;
                    let cause = self.cause.clone().unwrap_or_default();
                    let result = if self.rollback_failed {
                        PushResult::RollbackIncomplete { cause }
                    } else {
                        PushResult::RolledBack { cause }
                    };
                    for (name, reason) in &self.refusals {
                        if let Some(ParamOutcome::NotWritten { old }) = self.outcomes.get(name) {
                            let old = *old;
                            self.outcomes.insert(
                                name.clone(),
                                ParamOutcome::Refused {
                                    old,
                                    reason: reason.clone(),
                                },
                            );
                        }
                    }
                    return Step::Done(PushReport {
                        result,
                        outcomes: self.outcomes.clone(),
                        changed: 0,
                    });
                }
                Phase::Finished => {
                    return Step::Done(PushReport {
                        result: PushResult::RollbackIncomplete {
                            cause: "transaction already finished".into(),
                        },
                        outcomes: self.outcomes.clone(),
                        changed: 0,
                    });
                }
            }
        }
    }

    fn fail(&mut self, cause: String) {
        self.cause.get_or_insert(cause);
        // Restore in the reverse order of application: each state on the way back was an
        // accepted intermediate state on the way in.
        let mut restore = self.applied.clone();
        restore.extend(self.uncertain.iter().cloned());
        self.to_restore = restore;
        self.phase = Phase::Rollback;
    }

    /// The result of the last [`Step::Write`]: `Ok(echoed value)` or why it did not confirm.
    pub fn written(&mut self, result: Result<f32, StepError>) {
        let Some(c) = self.in_flight.take() else {
            return;
        };
        match self.phase {
            Phase::Apply => match result {
                Ok(v) if same_value(v, c.new) => {
                    self.pending.remove(self.cursor);
                    self.refusals.remove(&c.name);
                    self.applied.push(c);
                    self.progress_this_pass = true;
                }
                Ok(v) => {
                    self.refusals
                        .insert(c.name.clone(), format!("vehicle holds {v} after the write"));
                    self.cursor += 1;
                }
                Err(StepError::Refused(reason)) => {
                    self.refusals.insert(c.name.clone(), reason);
                    self.cursor += 1;
                }
                Err(StepError::Lost(reason)) => {
                    self.pending.remove(self.cursor);
                    self.uncertain.push(c.clone());
                    self.fail(format!("{}: {reason}", c.name));
                }
            },
            Phase::Rollback => {
                self.to_restore.pop();
                match result {
                    Ok(v) if same_value(v, c.old) => {
                        self.outcomes.insert(
                            c.name.clone(),
                            ParamOutcome::RolledBack {
                                old: c.old,
                                written: c.new,
                            },
                        );
                    }
                    Ok(v) => self.restore_failed(&c, Some(v), format!("vehicle holds {v}")),
                    Err(StepError::Refused(r) | StepError::Lost(r)) => {
                        self.restore_failed(&c, None, r);
                        self.to_inspect.push(c.name.clone());
                    }
                }
            }
            _ => {}
        }
    }

    fn restore_failed(&mut self, c: &Change, holds: Option<f32>, reason: String) {
        self.rollback_failed = true;
        self.outcomes.insert(
            c.name.clone(),
            ParamOutcome::RollbackFailed {
                old: c.old,
                holds,
                reason,
            },
        );
    }

    /// The result of the last [`Step::Read`].
    pub fn read(&mut self, result: Result<f32, StepError>) {
        match self.phase {
            Phase::Verify => {
                let Some(c) = self.in_flight.take() else {
                    return;
                };
                self.to_verify.pop();
                match result {
                    Ok(v) if same_value(v, c.new) => {}
                    Ok(v) => self.fail(format!(
                        "{}: read back {v}, expected {} (changed by someone else?)",
                        c.name, c.new
                    )),
                    Err(StepError::Refused(r) | StepError::Lost(r)) => {
                        self.fail(format!("{}: read-back failed: {r}", c.name));
                    }
                }
            }
            Phase::Inspect => {
                let Some(name) = self.to_inspect.pop() else {
                    return;
                };
                if let (Ok(v), Some(ParamOutcome::RollbackFailed { holds, .. })) =
                    (result, self.outcomes.get_mut(&name))
                {
                    *holds = Some(v);
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{MavParamType, Param};

    const F32: MavParamType = MavParamType::MAV_PARAM_TYPE_REAL32;

    fn twin_table() -> ParamSet {
        firmware_sim::nav::params::TABLE
            .iter()
            .map(|d| {
                (
                    d.name.to_owned(),
                    Param {
                        value: d.default as f32,
                        ty: F32,
                    },
                )
            })
            .collect()
    }

    fn change(cur: &ParamSet, name: &str, new: f32) -> Change {
        Change {
            name: name.into(),
            old: cur[name].value,
            new,
            ty: F32,
        }
    }

    /// A vehicle that follows `TwinRules` exactly, driven by the transaction.
    fn run(
        mut vehicle: ParamSet,
        changes: Vec<Change>,
        lose: &[&str],
    ) -> (PushReport, ParamSet, Vec<String>) {
        let mut t = Transaction::new(changes);
        let mut log = Vec::new();
        loop {
            match t.next_step() {
                Step::Write { name, value } => {
                    log.push(format!("w {name}={value}"));
                    if lose.contains(&name.as_str()) {
                        t.written(Err(StepError::Lost("timeout".into())));
                    } else if let Some(r) = TwinRules.refusal(&vehicle, &name, value) {
                        t.written(Err(StepError::Refused(r)));
                    } else {
                        vehicle.get_mut(&name).expect("known").value = value;
                        t.written(Ok(value));
                    }
                }
                Step::Read { name } => t.read(Ok(vehicle[&name].value)),
                Step::Done(r) => return (r, vehicle, log),
            }
        }
    }

    #[test]
    fn lowering_all_four_levels_needs_one_order_and_gets_it() {
        let cur = twin_table();
        let changes: Vec<Change> = [
            ("LAT_SAT_A", 0.4),
            ("LAT_SAT_B", 0.2),
            ("LAT_SAT_C", 0.1),
            ("LAT_SAT_D", 0.05),
        ]
        .iter()
        .map(|(n, v)| change(&cur, n, *v))
        .collect();
        let order = order_writes(&cur, &changes, &TwinRules);
        let names: Vec<&str> = order.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["LAT_SAT_D", "LAT_SAT_C", "LAT_SAT_B", "LAT_SAT_A"]);
        let (report, vehicle, _) = run(cur, order, &[]);
        assert_eq!(report.result, PushResult::Applied);
        assert_eq!(report.changed, 4);
        assert_eq!(vehicle["LAT_SAT_A"].value, 0.4);
    }

    #[test]
    fn given_order_is_retried_until_it_works() {
        // No planning: the vehicle refuses A, B, C first; passes retry after each progress.
        let cur = twin_table();
        let changes: Vec<Change> = [
            ("LAT_SAT_A", 0.4),
            ("LAT_SAT_B", 0.2),
            ("LAT_SAT_C", 0.1),
            ("LAT_SAT_D", 0.05),
        ]
        .iter()
        .map(|(n, v)| change(&cur, n, *v))
        .collect();
        let (report, vehicle, log) = run(cur, changes, &[]);
        assert_eq!(report.result, PushResult::Applied, "{log:?}");
        assert_eq!(vehicle["LAT_SAT_D"].value, 0.05);
    }

    #[test]
    fn an_impossible_change_rolls_back_the_valid_one() {
        let cur = twin_table();
        let changes = vec![change(&cur, "ALT_KP", 6.0), change(&cur, "LAT_SAT_B", 2.0)];
        let order = order_writes(&cur, &changes, &TwinRules);
        let (report, vehicle, log) = run(cur.clone(), order, &[]);
        assert_eq!(vehicle, cur, "{log:?}");
        let PushResult::RolledBack { cause } = &report.result else {
            panic!("{report:?}");
        };
        assert!(cause.contains("LAT_SAT_B"), "{cause}");
        assert!(matches!(
            report.outcomes["ALT_KP"],
            ParamOutcome::RolledBack { .. }
        ));
        assert!(
            matches!(&report.outcomes["LAT_SAT_B"], ParamOutcome::Refused { reason, .. } if reason.contains("a > b + c + d")),
            "{report:?}"
        );
    }

    #[test]
    fn a_lost_write_is_restored_too() {
        let cur = twin_table();
        let changes = vec![change(&cur, "ALT_KP", 6.0), change(&cur, "YAW_KP", 4.0)];
        let (report, vehicle, _) = run(cur.clone(), changes, &["YAW_KP"]);
        assert!(matches!(
            report.result,
            PushResult::RollbackIncomplete { .. } | PushResult::RolledBack { .. }
        ));
        assert_eq!(vehicle["ALT_KP"].value, cur["ALT_KP"].value);
    }
}
