//! `log plot` end to end through the library: a `firmware-sim simulate` flight (paper mode, the
//! paper's initial conditions) and tlogs written by this project's writer are drawn, and the
//! PNGs are checked from their pixels: every panel has its lines, no line pixel lies outside
//! its panel's plotting area, an outage stays a gap, the frame is the one asked for, and a
//! transition is drawn from the messages a VTOL sends (or refused, naming what is missing).

use std::ops::Range;
use std::path::Path;

use firmware_sim::model::airframe::ModelMode;
use firmware_sim::shell::simulate::{self, SimulateConfig};
use vtol_gcs::log::plot::{self, Figure, FlightData, Frame, Kind, PanelGeometry, PlotOptions};
use vtol_gcs::tlog::{Direction, Record, TlogWriter};
use vtol_link::Frame as MavFrame;
use vtol_link::dialect as apm;

fn simulate_csv(path: &Path) {
    let cfg = SimulateConfig {
        duration_s: 10.0,
        model: ModelMode::Paper,
        initial: simulate::parse_initial("phi=0.1,theta=0.1,psi=1,x=0.1,y=0.1,z=0.1").unwrap(),
        ..SimulateConfig::default()
    };
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    simulate::run(&cfg, Some(&mut out)).unwrap();
}

struct Png {
    w: u32,
    h: u32,
    rgb: Vec<u8>,
}

impl Png {
    fn read(path: &Path) -> Png {
        let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        Png {
            w: info.width,
            h: info.height,
            rgb: buf,
        }
    }

    /// A saturated colour: a series line (the mesh, text, frame, markers and setpoints are greys).
    fn is_line(&self, x: u32, y: u32) -> bool {
        let i = ((y * self.w + x) * 3) as usize;
        let (r, g, b) = (self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]);
        r.max(g).max(b) - r.min(g).min(b) > 60
    }

    fn line_pixels(&self, xs: Range<i32>, ys: Range<i32>) -> usize {
        let clamp = |v: i32, max: u32| u32::try_from(v.max(0)).unwrap().min(max);
        let mut n = 0;
        for y in clamp(ys.start, self.h)..clamp(ys.end, self.h) {
            for x in clamp(xs.start, self.w)..clamp(xs.end, self.w) {
                n += usize::from(self.is_line(x, y));
            }
        }
        n
    }
}

/// Line pixels outside every panel's plotting area.
fn strays(img: &Png, fig: &Figure) -> Vec<(u32, u32)> {
    let inside = |x: u32, y: u32, p: &PanelGeometry| {
        p.x_px.contains(&(x as i32)) && p.y_px.contains(&(y as i32))
    };
    let mut out = Vec::new();
    for y in 0..img.h {
        for x in 0..img.w {
            if img.is_line(x, y) && !fig.panels.iter().any(|p| inside(x, y, p)) {
                out.push((x, y));
            }
        }
    }
    out
}

fn assert_every_panel_drawn(img: &Png, fig: &Figure) {
    for p in &fig.panels {
        let n = img.line_pixels(p.x_px.clone(), p.y_px.clone());
        assert!(n > 200, "panel {} has {n} line pixels", p.title);
    }
}

fn opts(kind: Kind, frame: Frame, size: Option<(u32, u32)>) -> PlotOptions {
    PlotOptions {
        kind,
        frame,
        size,
        setpoint: None,
        title: None,
    }
}

fn draw(data: &FlightData, out: &Path, o: &PlotOptions) -> (Figure, Png) {
    let fig = plot::draw(data, None, out, o).unwrap();
    let img = Png::read(out);
    (fig, img)
}

/// A tlog of `msgs(i, t)` every 20 ms for `seconds`, skipping the times `skip` says.
fn write_tlog(
    path: &Path,
    seconds: u32,
    skip: impl Fn(f64) -> bool,
    msgs: impl Fn(u32, f64) -> Vec<apm::MavMessage>,
) {
    let mut w = TlogWriter::create(path).unwrap();
    let t0 = 1_795_346_880_000_000u64;
    for i in 0..seconds * 50 {
        let t = f64::from(i) * 0.02;
        if skip(t) {
            continue;
        }
        for m in msgs(i, t) {
            w.write(&Record {
                t_us: t0 + u64::from(i) * 20_000,
                direction: Direction::FromVehicle,
                frame: MavFrame::encode_v2(
                    vtol_link::SystemId(1),
                    vtol_link::ComponentId(1),
                    (i % 256) as u8,
                    &m,
                ),
            })
            .unwrap();
        }
    }
    w.flush().unwrap();
}

/// A hover: attitude, position and PWM; the ESCs and a surface jump between their extremes at
/// every sample (the worst case for a stroked polyline's joins).
fn hover(i: u32, t: f64) -> Vec<apm::MavMessage> {
    let ms = i * 20;
    let jump = |hi: u16, lo: u16| if i.is_multiple_of(2) { hi } else { lo };
    vec![
        apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
            time_boot_ms: ms,
            roll: (0.1 * (-t).exp()) as f32,
            pitch: if i.is_multiple_of(2) { 0.3 } else { -0.3 },
            yaw: (-0.3 * (-t).exp()) as f32,
            ..Default::default()
        }),
        apm::MavMessage::LOCAL_POSITION_NED(apm::LOCAL_POSITION_NED_DATA {
            time_boot_ms: ms,
            x: (0.98 * (1.0 - (-t).exp())) as f32,
            y: (0.1 * t.sin()) as f32,
            z: (-1.0 + 0.5 * (-t).exp()) as f32,
            ..Default::default()
        }),
        apm::MavMessage::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA {
            servo1_raw: jump(2000, 1000),
            servo2_raw: jump(1000, 2000),
            servo3_raw: 1500 + (i % 11) as u16,
            servo4_raw: jump(1900, 1100),
            servo5_raw: 1510,
            ..Default::default()
        }),
    ]
}

#[test]
fn simulate_csv_figures_have_every_panel_drawn_in_the_papers_frame() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("paper.csv");
    simulate_csv(&csv);
    let data = plot::load(&csv).unwrap();
    // stored in NED: roll = −φ, North = −x
    let att = data.attitude.as_ref().unwrap();
    assert!((att[0][0].1 + 0.1).abs() < 1e-6);
    assert!((data.position.as_ref().unwrap()[0][0].1 + 0.1).abs() < 1e-6);
    for (kind, panels) in [
        (Kind::Attitude, 3),
        (Kind::Position, 3),
        (Kind::Inputs, 4),
        (Kind::Pwm, 2),
    ] {
        let out = dir.path().join(format!("{kind:?}.png"));
        let (fig, img) = draw(&data, &out, &opts(kind, Frame::Paper, Some((900, 1000))));
        assert_eq!(fig.panels.len(), panels);
        assert_eq!((img.w, img.h), (900, 1000));
        assert_every_panel_drawn(&img, &fig);
        assert_eq!(strays(&img, &fig), vec![], "{kind:?}");
    }
    // the paper's φ starts at +0.1 rad
    let out = dir.path().join("att.png");
    let (fig, _) = draw(&data, &out, &opts(Kind::Attitude, Frame::Paper, None));
    assert_eq!(fig.panels[0].y_desc, "φ = −roll (rad)");
    assert!(fig.panels[0].y_range.1 > 0.1);
    // all: one column per figure, default size, each column filled by its own panels
    let out = dir.path().join("all.png");
    let (fig, img) = draw(&data, &out, &opts(Kind::All, Frame::Ned, None));
    assert_eq!(fig.panels.len(), 3 + 3 + 4 + 2);
    assert_eq!((img.w, img.h), (4 * 760, 90 + 4 * 260));
    let pwm_bottom = fig.panels.last().unwrap().y_px.end;
    assert!(
        pwm_bottom > i32::try_from(img.h).unwrap() - 80,
        "{pwm_bottom}"
    );
}

#[test]
fn no_line_leaves_its_panel() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("spiky.tlog");
    write_tlog(&tlog, 10, |_| false, hover);
    let data = plot::load(&tlog).unwrap();
    for (kind, size) in [
        (Kind::Pwm, (640, 700)),
        (Kind::Attitude, (640, 700)),
        (Kind::All, (1500, 900)),
    ] {
        let out = dir.path().join(format!("{kind:?}.png"));
        let (fig, img) = draw(&data, &out, &opts(kind, Frame::Ned, Some(size)));
        assert_every_panel_drawn(&img, &fig);
        let s = strays(&img, &fig);
        assert!(
            s.is_empty(),
            "{kind:?}: {} line pixels outside, e.g. {:?}",
            s.len(),
            &s[..s.len().min(5)]
        );
    }
}

#[test]
fn lines_drawn_over_each_other_stay_visible() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("same.tlog");
    // both ESCs command exactly the same PWM: ESC 2 lies on ESC 1 all along
    write_tlog(
        &tlog,
        5,
        |_| false,
        |i, t| {
            let mut m = hover(i, t);
            let esc = 1600 + (50.0 * (t * 2.0).sin()) as u16;
            m[2] = apm::MavMessage::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA {
                servo1_raw: esc,
                servo2_raw: esc,
                ..Default::default()
            });
            m
        },
    );
    let data = plot::load(&tlog).unwrap();
    let out = dir.path().join("pwm.png");
    let (fig, img) = draw(&data, &out, &opts(Kind::Pwm, Frame::Ned, Some((800, 700))));
    let rotors = &fig.panels[0];
    assert_eq!(rotors.lines, ["ESC 1", "ESC 2"]);
    let count = |rgb: [u8; 3]| {
        let mut n = 0;
        for y in rotors.y_px.clone() {
            for x in rotors.x_px.clone() {
                let i = ((y as u32 * img.w + x as u32) * 3) as usize;
                n += usize::from(img.rgb[i..i + 3] == rgb);
            }
        }
        n
    };
    // ESC 1 solid blue shows between ESC 2's orange dashes
    let (esc1, esc2) = (count([0x1f, 0x5f, 0xbf]), count([0xe3, 0x6c, 0x0a]));
    assert!(
        esc1 > 300 && esc2 > 300,
        "ESC 1: {esc1} px, ESC 2: {esc2} px"
    );
}

#[test]
fn an_outage_is_drawn_as_a_gap() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("outage.tlog");
    // 50 Hz, silent from 4 s to 6 s
    write_tlog(&tlog, 10, |t| (4.0..6.0).contains(&t), hover);
    let data = plot::load(&tlog).unwrap();
    let out = dir.path().join("outage.png");
    let (fig, img) = draw(
        &data,
        &out,
        &opts(Kind::Attitude, Frame::Ned, Some((900, 800))),
    );
    for p in &fig.panels {
        let col = |t: f64| p.column_of(t).round() as i32;
        let rows = p.y_px.clone();
        // lines on both sides, nothing in between (2 px for the stroke's width)
        assert!(
            img.line_pixels(col(3.0)..col(3.98), rows.clone()) > 20,
            "{}",
            p.title
        );
        assert!(
            img.line_pixels(col(6.0)..col(7.0), rows.clone()) > 20,
            "{}",
            p.title
        );
        let gap = img.line_pixels(col(3.98) + 3..col(6.0) - 2, rows);
        assert_eq!(gap, 0, "{}: the outage is bridged", p.title);
    }
}

#[test]
fn the_frame_is_the_users_and_setpoints_are_the_logs() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("hover.tlog");
    write_tlog(&tlog, 5, |_| false, hover);
    let data = plot::load(&tlog).unwrap();
    assert!(data.setpoint.is_none());
    let out = dir.path().join("pos.png");
    // NED by default: +0.98 m North is +0.98 on a "North" axis
    let (fig, _) = draw(&data, &out, &opts(Kind::Position, Frame::default(), None));
    let titles: Vec<&str> = fig.panels.iter().map(|p| p.title.as_str()).collect();
    assert_eq!(titles, ["North", "East", "Down"]);
    assert!(fig.panels[0].y_range.1 > 0.9 && fig.panels[0].y_range.0 > -0.1);
    assert_eq!(fig.panels[0].y_desc, "North (m)");
    // no setpoint in this log: none drawn
    assert!(
        fig.panels.iter().all(|p| p.lines.len() == 1),
        "{:?}",
        fig.panels[0].lines
    );
    // the paper's frame: x = −North
    let (fig, _) = draw(&data, &out, &opts(Kind::Position, Frame::Paper, None));
    assert_eq!(fig.panels[0].y_desc, "x = −North (m)");
    assert!(fig.panels[0].y_range.0 < -0.9 && fig.panels[0].y_range.1 < 0.1);
    // attitude in degrees in NED
    let (fig, _) = draw(&data, &out, &opts(Kind::Attitude, Frame::Ned, None));
    assert_eq!(fig.panels[0].y_desc, "roll, NED (°)");
    assert!(fig.panels[0].y_range.1 > 5.0, "0.1 rad is 5.7°");

    // a log with the vehicle's position target draws it
    let with_target = dir.path().join("target.tlog");
    write_tlog(
        &with_target,
        5,
        |_| false,
        |i, t| {
            let mut m = hover(i, t);
            m.push(apm::MavMessage::POSITION_TARGET_LOCAL_NED(
                apm::POSITION_TARGET_LOCAL_NED_DATA {
                    time_boot_ms: i * 20,
                    x: 1.0,
                    y: 0.0,
                    z: -1.0,
                    // the position is used (the type's default ignores x)
                    type_mask: apm::PositionTargetTypemask::empty(),
                    ..Default::default()
                },
            ));
            m
        },
    );
    let data = plot::load(&with_target).unwrap();
    let (fig, _) = draw(&data, &out, &opts(Kind::Position, Frame::Ned, None));
    assert_eq!(fig.panels[0].lines, ["North", "North target"]);
}

/// A tailsitter's forward transition as a VTOL reports it: pitch down to level flight while
/// the airspeed builds, the altitude held, the thrust raised, and EXTENDED_SYS_STATE's
/// vtol_state MC → TRANSITION_TO_FW → FW.
fn transition(i: u32, t: f64) -> Vec<apm::MavMessage> {
    let ms = i * 20;
    let s = ((t - 2.0) / 4.0).clamp(0.0, 1.0);
    let state = match t {
        t if t < 2.0 => apm::MavVtolState::MAV_VTOL_STATE_MC,
        t if t < 6.0 => apm::MavVtolState::MAV_VTOL_STATE_TRANSITION_TO_FW,
        _ => apm::MavVtolState::MAV_VTOL_STATE_FW,
    };
    let esc = 1600 + (200.0 * s) as u16;
    vec![
        apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
            time_boot_ms: ms,
            pitch: (-1.4 * s) as f32,
            ..Default::default()
        }),
        apm::MavMessage::VFR_HUD(apm::VFR_HUD_DATA {
            airspeed: (12.0 * s) as f32,
            alt: 120.0 + (0.5 * (s * 3.0).sin()) as f32,
            throttle: 60 + (20.0 * s) as u16,
            ..Default::default()
        }),
        apm::MavMessage::GLOBAL_POSITION_INT(apm::GLOBAL_POSITION_INT_DATA {
            time_boot_ms: ms,
            relative_alt: 20_000 + (500.0 * (s * 3.0).sin()) as i32,
            ..Default::default()
        }),
        apm::MavMessage::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA {
            servo1_raw: esc,
            servo2_raw: esc + 5,
            ..Default::default()
        }),
        apm::MavMessage::EXTENDED_SYS_STATE(apm::EXTENDED_SYS_STATE_DATA {
            vtol_state: state,
            ..Default::default()
        }),
    ]
}

#[test]
fn a_transition_is_pitch_airspeed_altitude_and_thrust() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("transition.tlog");
    write_tlog(&tlog, 8, |_| false, transition);
    let data = plot::load(&tlog).unwrap();
    let states: Vec<&str> = data.vtol_states.iter().map(|(_, s)| s.as_str()).collect();
    assert_eq!(states, ["MC", "to FW", "FW"]);
    let out = dir.path().join("transition.png");
    let (fig, img) = draw(
        &data,
        &out,
        &opts(Kind::Transition, Frame::Ned, Some((800, 1000))),
    );
    let titles: Vec<&str> = fig.panels.iter().map(|p| p.title.as_str()).collect();
    assert_eq!(titles, ["pitch", "airspeed", "altitude", "thrust"]);
    assert_eq!(fig.panels[2].y_desc, "altitude above home (m)");
    assert_eq!(fig.panels[3].lines, ["ESC 1", "ESC 2"]);
    // pitch in degrees: level flight is −80°
    assert!(fig.panels[0].y_range.0 < -80.0);
    assert_every_panel_drawn(&img, &fig);
    assert_eq!(strays(&img, &fig), vec![]);

    // without VFR_HUD there is no airspeed: one clear error that names it
    let hover_log = dir.path().join("hover.tlog");
    write_tlog(&hover_log, 2, |_| false, hover);
    let e = plot::draw(
        &plot::load(&hover_log).unwrap(),
        None,
        &out,
        &opts(Kind::Transition, Frame::Ned, None),
    )
    .unwrap_err()
    .to_string();
    assert_eq!(e, "cannot plot transition: no airspeed (VFR_HUD)");
}

#[test]
fn the_twins_controller_outputs_in_a_tlog_are_the_inputs_figure() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("inputs.tlog");
    let names = firmware_sim::endpoint::streams::CONTROLLER_OUTPUT_NAMES;
    write_tlog(
        &path,
        4,
        |_| false,
        |i, _| {
            names
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    apm::MavMessage::NAMED_VALUE_FLOAT(apm::NAMED_VALUE_FLOAT_DATA {
                        time_boot_ms: i * 20,
                        value: (k as f32 + 1.0) * (i as f32 * 0.05).sin(),
                        name: (*name).into(),
                    })
                })
                .collect()
        },
    );
    let data = plot::load(&path).unwrap();
    let inputs = data.inputs.as_ref().expect("inputs from NAMED_VALUE_FLOAT");
    assert!(inputs.iter().all(|s| s.len() == 200));
    let out = dir.path().join("inputs.png");
    let (fig, img) = draw(
        &data,
        &out,
        &opts(Kind::Inputs, Frame::Paper, Some((800, 900))),
    );
    assert_eq!(fig.panels.len(), 4);
    assert_every_panel_drawn(&img, &fig);
    // this tlog has no attitude: one clear error
    let e = plot::draw(&data, None, &out, &opts(Kind::Attitude, Frame::Ned, None)).unwrap_err();
    assert!(e.to_string().contains("no ATTITUDE"), "{e}");
}

#[test]
fn a_compared_simulation_shares_the_axes() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("flight.tlog");
    write_tlog(&tlog, 10, |_| false, hover);
    let csv = dir.path().join("paper.csv");
    simulate_csv(&csv);
    let logged = plot::load(&tlog).unwrap();
    let offline = plot::load(&csv).unwrap();
    let out = dir.path().join("cmp.png");
    let fig = plot::draw(
        &logged,
        Some(&offline),
        &out,
        &opts(Kind::All, Frame::Paper, Some((1800, 1200))),
    )
    .unwrap();
    // attitude, position, inputs (from the CSV only), pwm
    assert_eq!(fig.panels.len(), 12);
    assert_eq!(fig.panels[0].lines, ["φ (flight.tlog)", "φ (paper.csv)"]);
    let img = Png::read(&out);
    assert_every_panel_drawn(&img, &fig);
    assert_eq!(strays(&img, &fig), vec![]);
}

#[test]
fn errors_are_one_line_in_words() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("bad.csv");
    std::fs::write(&csv, "t,phi,theta,psi\n0,0.1,0,0\n0.01,nan,0,0\n").unwrap();
    let e = plot::load(&csv).unwrap_err().to_string();
    assert!(e.contains("row 3") && e.contains("phi"), "{e}");
    // a PNG that cannot be written: the system's reason, not a Debug dump
    std::fs::write(&csv, "t,phi,theta,psi\n0,0.1,0,0\n0.01,0.2,0,0\n").unwrap();
    let data = plot::load(&csv).unwrap();
    let out = dir.path().join("no such dir").join("a.png");
    let e = plot::draw(&data, None, &out, &opts(Kind::Attitude, Frame::Ned, None))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("cannot write ") && e.ends_with("No such file or directory (os error 2)"),
        "{e}"
    );
    assert!(
        !e.contains('\n') && !e.contains("Os {") && !e.contains("Error("),
        "{e}"
    );
}
