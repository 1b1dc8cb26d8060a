//! What an upload checks before and after: a file read and checked as the command line and
//! the terminal UI both do it ([`load`]), and how the list the vehicle holds afterwards differs
//! from what was sent ([`difference`]).

use std::path::Path;

use vtol_link::text_file;

use super::{Item, Kind, check, command_name, file, frame_name};

/// Reads and checks a file: its items, or every problem, each naming where it is (the
/// file's name first).
///
/// # Errors
/// Every problem found, one a line; nothing is sent with any.
pub fn load(path: &Path, kind: Kind) -> Result<Vec<Item>, Vec<String>> {
    let name = path.display();
    let text = text_file::read_text(path).map_err(|e| vec![e.to_string()])?;
    let items = file::read(&text, kind).map_err(|e| vec![format!("{name}: {e}")])?;
    let problems = check::problems(&items, kind);
    if !problems.is_empty() {
        return Err(problems
            .into_iter()
            .map(|p| format!("{name}: {p}"))
            .collect());
    }
    Ok(items.into_iter().map(|l| l.item).collect())
}

/// How the vehicle's list differs from what was sent, if it does ([`Item::held_as`]). A
/// mission's item 0 is home, which ArduPilot replaces with the real one: only its presence is
/// compared. Fence and rally items have no use for `autocontinue` (ArduPilot reports 0
/// whatever was sent).
#[must_use]
pub fn difference(sent: &[Item], back: &[Item], kind: Kind) -> Option<String> {
    if sent.len() != back.len() {
        return Some(format!("{} items, not {}", back.len(), sent.len()));
    }
    let skip = usize::from(kind == Kind::Mission);
    sent.iter()
        .zip(back)
        .enumerate()
        .skip(skip)
        .find(|(_, (a, b))| {
            let mut a = **a;
            if kind != Kind::Mission {
                a.autocontinue = b.autocontinue;
            }
            !a.held_as(b)
        })
        .map(|(seq, (a, b))| format!("item {seq} is {}; sent {}", describe(b), describe(a)))
}

/// An item in one line of words, every field.
#[must_use]
pub fn describe(i: &Item) -> String {
    let [p1, p2, p3, p4] = i.params;
    format!(
        "{} frame {} at {}, {} alt {} params {p1} {p2} {p3} {p4} autocontinue {}",
        command_name(i.command),
        frame_name(i.frame),
        i.x,
        i.y,
        i.z,
        u8::from(i.autocontinue)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_mission_s_home_may_differ() {
        let text = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.363262\t149.165237\t584.09\t1\n\
                    1\t0\t3\t84\t0\t0\t0\t0\t0\t0\t30\t1\n";
        let sent: Vec<Item> = file::read(text, Kind::Mission)
            .expect("reads")
            .into_iter()
            .map(|l| l.item)
            .collect();
        let mut back = sent.clone();
        back[0].z = 600.0;
        assert_eq!(difference(&sent, &back, Kind::Mission), None);
        assert!(difference(&sent, &back, Kind::Rally).is_some());
        back[1].autocontinue = false;
        assert!(
            difference(&sent[1..], &back[1..], Kind::Rally).is_none(),
            "no autocontinue"
        );
        back[1].z = 31.0;
        assert_eq!(
            difference(&sent, &back, Kind::Mission).as_deref(),
            Some(
                "item 1 is NAV_VTOL_TAKEOFF frame GLOBAL_RELATIVE_ALT at 0, 0 alt 31 params 0 0 0 0 \
                 autocontinue 0; sent NAV_VTOL_TAKEOFF frame GLOBAL_RELATIVE_ALT at 0, 0 alt 30 \
                 params 0 0 0 0 autocontinue 1"
            )
        );
        assert!(difference(&sent, &back[..1], Kind::Mission).is_some());
    }
}
