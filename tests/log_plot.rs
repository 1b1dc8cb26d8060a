//! `log plot` end to end through the library: a `firmware-sim simulate` flight (paper mode, the
//! paper's initial conditions) and a tlog written by this project's writer are drawn; each PNG
//! must decode, have the expected size, and hold drawn series pixels in every panel.

use std::path::Path;

use firmware_sim::model::airframe::ModelMode;
use firmware_sim::shell::simulate::{self, SimulateConfig};
use vtol_gcs::log::plot::{self, Kind, PlotOptions};
use vtol_gcs::tlog::{Direction, Record, TlogWriter};
use vtol_link::Frame;
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

fn read_png(path: &Path) -> Png {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "plotters writes RGB");
    buf.truncate(info.buffer_size());
    Png {
        w: info.width,
        h: info.height,
        rgb: buf,
    }
}

/// Pixels of a saturated colour (series lines; the mesh, text and frame are greys) in a box.
fn coloured_pixels(img: &Png, x0: u32, x1: u32, y0: u32, y1: u32) -> usize {
    let mut n = 0;
    for y in y0..y1 {
        for x in x0..x1 {
            let i = ((y * img.w + x) * 3) as usize;
            let (r, g, b) = (img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]);
            let max = r.max(g).max(b);
            let min = r.min(g).min(b);
            if max - min > 60 {
                n += 1;
            }
        }
    }
    n
}

/// Every panel of a rows × cols grid (below the title) has drawn series pixels.
fn assert_panels_drawn(img: &Png, rows: u32, cols: u32, panels: usize) {
    let title = 40;
    let ph = (img.h - title) / rows;
    let pw = img.w / cols;
    let mut drawn = 0;
    for c in 0..cols {
        for r in 0..rows {
            let y0 = title + r * ph;
            if coloured_pixels(img, c * pw, (c + 1) * pw, y0, y0 + ph) > 200 {
                drawn += 1;
            }
        }
    }
    assert_eq!(drawn, panels, "panels with a drawn series");
}

fn opts(kind: Kind, size: Option<(u32, u32)>) -> PlotOptions {
    PlotOptions {
        kind,
        size,
        setpoint: [0.0, 0.0, 1.0],
        title: None,
    }
}

#[test]
fn simulate_csv_figures_have_every_panel_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("paper.csv");
    simulate_csv(&csv);
    let data = plot::load(&csv).unwrap();
    for (kind, rows, panels) in [
        (Kind::Attitude, 3, 3),
        (Kind::Position, 3, 3),
        (Kind::Inputs, 4, 4),
        (Kind::Pwm, 2, 2),
    ] {
        let out = dir.path().join(format!("{kind:?}.png"));
        let n = plot::draw(&data, None, &out, &opts(kind, Some((900, 1000)))).unwrap();
        assert_eq!(n, panels);
        let img = read_png(&out);
        assert_eq!((img.w, img.h), (900, 1000));
        assert_panels_drawn(&img, rows, 1, panels);
    }
    // all: one column per figure, default size
    let out = dir.path().join("all.png");
    let n = plot::draw(&data, None, &out, &opts(Kind::All, None)).unwrap();
    assert_eq!(n, 3 + 3 + 4 + 2);
    let img = read_png(&out);
    assert_eq!((img.w, img.h), (4 * 760, 90 + 4 * 260));
}

fn write_tlog(path: &Path, seconds: u32) {
    let mut w = TlogWriter::create(path).unwrap();
    let t0 = 1_795_346_880_000_000u64;
    for i in 0..seconds * 50 {
        let t = f64::from(i) * 0.02;
        let ms = i * 20;
        let msgs = [
            apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
                time_boot_ms: ms,
                roll: (0.1 * (-t).exp()) as f32,
                pitch: (0.05 * (t * 2.0).sin()) as f32,
                yaw: (-0.3 * (-t).exp()) as f32,
                ..Default::default()
            }),
            apm::MavMessage::LOCAL_POSITION_NED(apm::LOCAL_POSITION_NED_DATA {
                time_boot_ms: ms,
                x: (0.2 * (-t).exp()) as f32,
                y: (0.1 * t.sin()) as f32,
                z: (-1.0 + 0.5 * (-t).exp()) as f32,
                ..Default::default()
            }),
            apm::MavMessage::SERVO_OUTPUT_RAW(apm::SERVO_OUTPUT_RAW_DATA {
                servo1_raw: 1681 + (i % 7) as u16,
                servo2_raw: 1679,
                servo3_raw: 1500 + (i % 11) as u16,
                servo4_raw: 1490,
                servo5_raw: 1510,
                ..Default::default()
            }),
        ];
        for m in &msgs {
            w.write(&Record {
                t_us: t0 + u64::from(ms) * 1000,
                direction: Direction::FromVehicle,
                frame: Frame::encode_v2(
                    vtol_link::SystemId(1),
                    vtol_link::ComponentId(1),
                    (i % 256) as u8,
                    m,
                ),
            })
            .unwrap();
        }
    }
    w.flush().unwrap();
}

#[test]
fn a_tlog_and_a_compared_simulation_share_the_axes() {
    let dir = tempfile::tempdir().unwrap();
    let tlog = dir.path().join("flight.tlog");
    write_tlog(&tlog, 10);
    let csv = dir.path().join("paper.csv");
    simulate_csv(&csv);
    let logged = plot::load(&tlog).unwrap();
    // paper frame: φ = −roll, z = −z_ned
    let att = logged.attitude.as_ref().unwrap();
    assert!((att[0][0].1 + 0.1).abs() < 1e-6);
    let pos = logged.position.as_ref().unwrap();
    assert!((pos[2][0].1 - 0.5).abs() < 1e-6);
    assert!(logged.inputs.is_none());
    let offline = plot::load(&csv).unwrap();
    let out = dir.path().join("cmp.png");
    let n = plot::draw(
        &logged,
        Some(&offline),
        &out,
        &opts(Kind::All, Some((1800, 1200))),
    )
    .unwrap();
    // attitude, position, inputs (from the CSV only), pwm
    assert_eq!(n, 12);
    let img = read_png(&out);
    assert_eq!((img.w, img.h), (1800, 1200));
    assert_panels_drawn(&img, 4, 4, 12);
    // this tlog has no controller outputs: one clear error
    let e = plot::draw(&logged, None, &out, &opts(Kind::Inputs, None)).unwrap_err();
    assert!(e.to_string().contains("NAMED_VALUE_FLOAT"), "{e}");
}

#[test]
fn the_twins_controller_outputs_in_a_tlog_are_the_inputs_figure() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("inputs.tlog");
    let mut w = TlogWriter::create(&path).unwrap();
    let names = firmware_sim::endpoint::streams::CONTROLLER_OUTPUT_NAMES;
    for i in 0..200u32 {
        for (k, name) in names.iter().enumerate() {
            let msg = apm::MavMessage::NAMED_VALUE_FLOAT(apm::NAMED_VALUE_FLOAT_DATA {
                time_boot_ms: i * 20,
                value: (k as f32 + 1.0) * (i as f32 * 0.05).sin(),
                name: (*name).into(),
            });
            w.write(&Record {
                t_us: 1_795_346_880_000_000 + u64::from(i) * 20_000,
                direction: Direction::FromVehicle,
                frame: Frame::encode_v2(
                    vtol_link::SystemId(1),
                    vtol_link::ComponentId(1),
                    (i % 256) as u8,
                    &msg,
                ),
            })
            .unwrap();
        }
    }
    w.flush().unwrap();
    let data = plot::load(&path).unwrap();
    let inputs = data.inputs.as_ref().expect("inputs from NAMED_VALUE_FLOAT");
    assert!(inputs.iter().all(|s| s.len() == 200));
    let out = dir.path().join("inputs.png");
    assert_eq!(
        plot::draw(&data, None, &out, &opts(Kind::Inputs, Some((800, 900)))).unwrap(),
        4
    );
    assert_panels_drawn(&read_png(&out), 4, 1, 4);
}

#[test]
fn a_broken_csv_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("bad.csv");
    std::fs::write(&csv, "t,phi,theta,psi\n0,0.1,0,0\n0.01,nan,0,0\n").unwrap();
    let e = plot::load(&csv).unwrap_err().to_string();
    assert!(e.contains("row 3") && e.contains("phi"), "{e}");
}
