//! What each servo output drives, from its `SERVOn_FUNCTION` parameter in ArduPilot's numbering
//! (`SRV_Channel::Function` in ArduPilot's SRV_Channel.h; the twin publishes the same numbers
//! for its own outputs). The terminal UI labels its Outputs pane with these names and
//! `vtol-gcs log plot` its PWM legends; an output whose function is unknown, disabled or not
//! published is `SERVOn`.

/// One output as labelled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Output {
    /// What it drives (`left motor`, `right elevon`, `motor 3`), or `SERVOn`.
    pub name: String,
    /// Whether it drives a motor (throttle, a multicopter motor): charted with the rotors.
    pub motor: bool,
}

/// The name of ArduPilot output function `f`, and whether it is a motor. `None` for 0
/// (disabled: a plain PWM output) and for numbers this table does not know.
#[must_use]
pub fn function_name(f: i32) -> Option<(String, bool)> {
    let fixed = |s: &str| Some((s.to_owned(), false));
    let motor = |s: String| Some((s, true));
    match f {
        1 => fixed("RC passthru"),
        2 => fixed("flap"),
        3 => fixed("auto flap"),
        4 => fixed("aileron"),
        6 => fixed("mount pan"),
        7 => fixed("mount tilt"),
        8 => fixed("mount roll"),
        9 => fixed("mount open"),
        10 => fixed("camera"),
        16 => fixed("L spoiler 1"),
        17 => fixed("R spoiler 1"),
        18 => fixed("aileron"),
        19 | 20 => fixed("elevator"),
        21 => fixed("rudder"),
        24 => fixed("left flaperon"),
        25 => fixed("right flaperon"),
        26 => fixed("steering"),
        27 => fixed("parachute"),
        28 => fixed("gripper"),
        29 => fixed("landing gear"),
        30 => fixed("engine run"),
        33..=40 => motor(format!("motor {}", f - 32)),
        41 => fixed("motor tilt"),
        45 => fixed("rear tilt"),
        46 => fixed("rear L tilt"),
        47 => fixed("rear R tilt"),
        51..=66 => fixed(&format!("RC in {}", f - 50)),
        67 => fixed("ignition"),
        69 => fixed("starter"),
        70 => motor("throttle".to_owned()),
        73 => motor("left motor".to_owned()),
        74 => motor("right motor".to_owned()),
        75 => fixed("left tilt"),
        76 => fixed("right tilt"),
        77 => fixed("left elevon"),
        78 => fixed("right elevon"),
        79 => fixed("left V-tail"),
        80 => fixed("right V-tail"),
        81 => motor("boost motor".to_owned()),
        82..=85 => motor(format!("motor {}", f - 73)),
        86 => fixed("L spoiler 2"),
        87 => fixed("R spoiler 2"),
        94..=109 => fixed(&format!("script {}", f - 93)),
        110 => fixed("airbrake"),
        124 => fixed("roll out"),
        125 => fixed("pitch out"),
        126 => motor("thrust out".to_owned()),
        127 => fixed("yaw out"),
        160..=179 => motor(format!("motor {}", f - 147)),
        _ => None,
    }
}

/// Labels for outputs 1, 2, … from their `SERVOn_FUNCTION` values (`None`: not published).
/// Two outputs with the aileron function are the left and the right one in output order (the
/// twin's and ArduPlane's usual wiring); more are numbered.
#[must_use]
pub fn outputs(functions: &[Option<f32>]) -> Vec<Output> {
    let ailerons = functions
        .iter()
        .filter(|f| matches!(f.map(|v| v as i32), Some(4 | 18)))
        .count();
    let mut aileron = 0;
    functions
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let plain = Output {
                name: format!("SERVO{}", i + 1),
                motor: false,
            };
            let Some((mut name, motor)) = f.and_then(|v| function_name(v as i32)) else {
                return plain;
            };
            if name == "aileron" {
                aileron += 1;
                name = match (ailerons, aileron) {
                    (2, 1) => "left aileron".to_owned(),
                    (2, _) => "right aileron".to_owned(),
                    (1, _) => name,
                    (_, n) => format!("aileron {n}"),
                };
            }
            Output { name, motor }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(f: &[Option<f32>]) -> Vec<String> {
        outputs(f).into_iter().map(|o| o.name).collect()
    }

    #[test]
    fn the_twins_and_arduplanes_tailsitter_outputs_are_named_by_what_they_drive() {
        // The twin: right and left motor, two ailerons, the elevator.
        let twin = [74.0, 73.0, 4.0, 4.0, 19.0].map(Some);
        assert_eq!(
            names(&twin),
            [
                "right motor",
                "left motor",
                "left aileron",
                "right aileron",
                "elevator"
            ]
        );
        // ArduPlane's tailsitter example: elevons and two throttles.
        let plane = [77.0, 78.0, 73.0, 74.0].map(Some);
        assert_eq!(
            names(&plane),
            ["left elevon", "right elevon", "left motor", "right motor"]
        );
        let o = outputs(&plane);
        assert_eq!(
            o.iter().map(|o| o.motor).collect::<Vec<_>>(),
            [false, false, true, true]
        );
    }

    #[test]
    fn unknown_disabled_or_unpublished_functions_are_servon() {
        let f = [
            Some(0.0),
            None,
            Some(999.0),
            Some(33.0),
            Some(40.0),
            Some(160.0),
        ];
        assert_eq!(
            names(&f),
            [
                "SERVO1", "SERVO2", "SERVO3", "motor 1", "motor 8", "motor 13"
            ]
        );
        assert_eq!(names(&[Some(4.0)]), ["aileron"]);
        assert_eq!(
            names(&[Some(4.0), Some(4.0), Some(4.0)]),
            ["aileron 1", "aileron 2", "aileron 3"]
        );
        assert_eq!(names(&[Some(82.0), Some(21.0)]), ["motor 9", "rudder"]);
    }
}
