//! Draws the airframe's lift and drag coefficients and its lift-to-drag ratio over 0–90° of
//! angle of attack (`physical` mode's aerodynamic model, `docs/model.md`).
//!
//! Run: `cargo run -p firmware-sim --example aero_polar -- docs/figures/aero_lift_drag.png`

use firmware_sim::model::plant::aero::lift_drag_coefficients;
use plotters::coord::types;
use plotters::prelude::*;
use plotters::style::FontStyle;

static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

type AngleChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<types::RangedCoordf64, types::RangedCoordf64>>;

/// A chart over 0–90° of angle of attack and 0–`y_max`, its mesh drawn.
fn angle_chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    caption: &str,
    y_max: f64,
) -> Result<AngleChart<'a, 'b>, Box<dyn std::error::Error>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(0.0..90.0, 0.0..y_max)?;
    chart
        .configure_mesh()
        .x_desc("angle of attack, deg")
        .label_style(("sans-serif", 13))
        .draw()?;
    Ok(chart)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "aero_lift_drag.png".to_owned());
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES)
        .map_err(|_| "the bundled font does not load")?;
    let curve: Vec<(f64, f64, f64)> = (0..=900)
        .map(|i| {
            let a = f64::from(i) * 0.1;
            let (cl, cd) = lift_drag_coefficients(a.to_radians());
            (a, cl, cd)
        })
        .collect();
    let root = BitMapBackend::new(&out, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(500);
    let mut c = angle_chart(&left, "C_L, C_D (flat plate, AR 1.3)", 1.3)?;
    c.draw_series(LineSeries::new(curve.iter().map(|p| (p.0, p.1)), &BLUE))?
        .label("C_L")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    c.draw_series(LineSeries::new(curve.iter().map(|p| (p.0, p.2)), &RED))?
        .label("C_D")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    c.configure_series_labels()
        .label_font(("sans-serif", 13))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    let mut d = angle_chart(&right, "L/D", 6.0)?;
    d.draw_series(LineSeries::new(
        curve.iter().map(|p| (p.0, p.1 / p.2)),
        &BLACK,
    ))?;
    root.present()?;
    println!("wrote {out}");
    Ok(())
}
