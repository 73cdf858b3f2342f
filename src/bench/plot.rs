//! PNG plots of a bench report, drawn with plotters into memory and written atomically:
//! `convergence.png` (the perturbation runs' mean camera and LiDAR errors against iteration, one
//! line per run, like the paper's Fig. A1) and `error-vs-perturbation.png` (final error against
//! the initial rotation and translation error, mean ± std over seeds per method).
//!
//! The text face is egui's bundled Ubuntu Light, so plots need no system fonts.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::case::{CaseResult, Errors};
use super::report::{BenchReport, stat};
use super::suite::Protocol;

const FONT: &str = "sans-serif";
const SIZE: (u32, u32) = (1400, 900);

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bundled font is valid; if it were not, text would be missing, not the plot.
        let _ = plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            epaint_default_fonts::UBUNTU_LIGHT,
        );
    });
}

/// Draw into an RGB buffer and write it as PNG, atomically.
fn render(
    path: &Path,
    draw: impl FnOnce(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
) -> Result<(), String> {
    register_font();
    let mut buf = vec![255u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        draw(&root)?;
        root.present().map_err(|e| e.to_string())?;
    }
    let img = image::RgbImage::from_raw(SIZE.0, SIZE.1, buf).ok_or("plot buffer size")?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| format!("cannot encode {}: {e}", path.display()))?;
    crate::util::write_atomic(path, &png)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// The four error quantities a panel can show.
const QUANTITIES: [(&str, fn(&Errors) -> Option<f64>); 4] = [
    ("camera rotation error (°)", |e| e.camera_rotation_deg),
    ("camera translation error (cm)", |e| e.camera_translation_cm),
    ("LiDAR rotation error (°)", |e| e.lidar_rotation_deg),
    ("LiDAR translation error (cm)", |e| e.lidar_translation_cm),
];

/// Smallest error a log axis shows (errors of sensors that started exact are ~1e-14).
const LOG_FLOOR: f64 = 1e-3;

/// Log-scale bounds around the values (floored at [`LOG_FLOOR`]; a decade when flat).
fn log_bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in values.filter(|v| v.is_finite()).map(|v| v.max(LOG_FLOOR)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.01, 10.0);
    }
    (lo / 1.5, (hi * 1.5).max(lo * 10.0))
}

/// Tick labels with as many decimals as the value needs.
fn tick(v: &f64) -> String {
    let a = v.abs();
    if a >= 10.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else if a >= 0.1 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// Convergence curves of the perturbation protocol's runs (one line per run, colour per run).
pub fn convergence(report: &BenchReport, path: &Path) -> Result<(), super::BenchError> {
    let runs: Vec<(String, &CaseResult)> = report
        .cases
        .iter()
        .filter(|c| c.protocol == Protocol::Perturbation)
        .filter_map(|c| {
            let r = report.result(c)?;
            let label = format!("{}, {}, seed {}", c.method.label(), c.row, c.seed);
            Some((label, r)).filter(|_| r.error.is_none() && r.curve.len() > 1)
        })
        .collect();
    Ok(render(path, |root| {
        let err = |e: DrawingAreaErrorKind<_>| e.to_string();
        let (title, body) = root.split_vertically(50);
        title
            .titled(
                &format!(
                    "Convergence: errors after root alignment against iteration ({} suite)",
                    report.suite
                ),
                (FONT, 28),
            )
            .map_err(err)?;
        let panels = body.split_evenly((2, 2));
        for (panel, (name, get)) in panels.iter().zip(QUANTITIES) {
            let lines: Vec<(&String, Vec<(f64, f64)>)> = runs
                .iter()
                .map(|(label, r)| {
                    let pts = r
                        .curve
                        .iter()
                        .filter_map(|p| Some((p.step as f64, get(&p.errors)?.max(LOG_FLOOR))))
                        .collect();
                    (label, pts)
                })
                .filter(|(_, pts): &(&String, Vec<(f64, f64)>)| !pts.is_empty())
                .collect();
            let x_max = lines
                .iter()
                .flat_map(|(_, p)| p.iter().map(|(x, _)| *x))
                .fold(1.0, f64::max);
            let (lo, hi) = log_bounds(lines.iter().flat_map(|(_, p)| p.iter().map(|(_, y)| *y)));
            let mut chart = ChartBuilder::on(panel)
                .margin(12)
                .caption(name, (FONT, 22))
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..x_max, (lo..hi).log_scale())
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_desc("iteration")
                .y_desc(name)
                .y_label_formatter(&tick)
                .label_style((FONT, 16))
                .draw()
                .map_err(err)?;
            if lines.is_empty() {
                chart
                    .draw_series(std::iter::once(Text::new(
                        "not estimated by these runs",
                        (x_max * 0.3, (lo * hi).sqrt()),
                        (FONT, 20),
                    )))
                    .map_err(err)?;
            }
            for (i, (label, pts)) in lines.into_iter().enumerate() {
                let colour = Palette99::pick(i).to_rgba();
                chart
                    .draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                    .map_err(err)?
                    .label(label.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font((FONT, 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(err)?;
        }
        Ok(())
    })?)
}

/// Final error against the initial perturbation, per method (mean ± std over seeds).
pub fn error_vs_perturbation(report: &BenchReport, path: &Path) -> Result<(), super::BenchError> {
    // (method, quantity index) → points (initial level, final stat) for rotation and translation
    // sweeps separately.
    let mut methods: Vec<&'static str> = Vec::new();
    for c in report
        .cases
        .iter()
        .filter(|c| c.protocol == Protocol::Perturbation)
    {
        if !methods.contains(&c.method.label()) {
            methods.push(c.method.label());
        }
    }
    let series = |method: &str, rotation_sweep: bool, get: fn(&Errors) -> Option<f64>| {
        let mut levels: Vec<f64> = Vec::new();
        let cases = report.cases.iter().filter(|c| {
            c.protocol == Protocol::Perturbation
                && c.method.label() == method
                && (if rotation_sweep {
                    c.perturb_deg > 0.0
                } else {
                    c.perturb_cm > 0.0
                })
        });
        let cases: Vec<_> = cases.collect();
        for c in &cases {
            let level = if rotation_sweep {
                c.perturb_deg
            } else {
                c.perturb_cm
            };
            if !levels.contains(&level) {
                levels.push(level);
            }
        }
        levels
            .into_iter()
            .filter_map(|level| {
                let values: Vec<f64> = cases
                    .iter()
                    .filter(|c| {
                        (if rotation_sweep {
                            c.perturb_deg
                        } else {
                            c.perturb_cm
                        }) == level
                    })
                    .filter_map(|c| report.result(c))
                    .filter(|r| r.error.is_none())
                    .filter_map(|r| get(&r.result))
                    .collect();
                Some((level, stat(&values)?))
            })
            .collect::<Vec<_>>()
    };
    Ok(render(path, |root| {
        let err = |e: DrawingAreaErrorKind<_>| e.to_string();
        let (title, body) = root.split_vertically(50);
        title
            .titled(
                &format!(
                    "Final error against initial error (mean ± std over seeds; {} suite)",
                    report.suite
                ),
                (FONT, 28),
            )
            .map_err(err)?;
        let panels = body.split_evenly((2, 2));
        // Rows: rotation sweep (x: initial °), translation sweep (x: initial cm);
        // columns: rotation error, translation error.
        let layout = [
            (true, 0usize, "initial rotation error (°)"),
            (true, 1, "initial rotation error (°)"),
            (false, 0, "initial translation error (cm)"),
            (false, 1, "initial translation error (cm)"),
        ];
        for (panel, (rotation_sweep, which, x_desc)) in panels.iter().zip(layout) {
            let (cam, lidar) = (QUANTITIES[which], QUANTITIES[which + 2]);
            let y_name = if which == 0 {
                "final rotation error (°)"
            } else {
                "final translation error (cm)"
            };
            let mut lines = Vec::new();
            for m in &methods {
                for (who, (_, get)) in [("cameras", cam), ("LiDARs", lidar)] {
                    let pts = series(m, rotation_sweep, get);
                    if !pts.is_empty() {
                        lines.push((format!("{m}: {who}"), pts));
                    }
                }
            }
            let xs = lines.iter().flat_map(|(_, p)| p.iter().map(|(x, _)| *x));
            let x_max = xs.fold(1.0, f64::max) * 1.15;
            let hi = lines
                .iter()
                .flat_map(|(_, p)| p.iter().map(|(_, s)| s.mean + s.std))
                .fold(0.0f64, f64::max)
                .max(1e-3)
                * 1.2;
            let mut chart = ChartBuilder::on(panel)
                .margin(12)
                .caption(
                    format!(
                        "{} sweep: {y_name}",
                        if rotation_sweep {
                            "rotation"
                        } else {
                            "translation"
                        }
                    ),
                    (FONT, 22),
                )
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..x_max, 0.0..hi)
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_name)
                .y_label_formatter(&tick)
                .label_style((FONT, 16))
                .draw()
                .map_err(err)?;
            for (i, (label, pts)) in lines.into_iter().enumerate() {
                let colour = Palette99::pick(i).to_rgba();
                let line: Vec<(f64, f64)> = pts.iter().map(|(x, s)| (*x, s.mean)).collect();
                chart
                    .draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))
                    .map_err(err)?
                    .label(label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
                chart
                    .draw_series(line.iter().map(|p| Circle::new(*p, 5, colour.filled())))
                    .map_err(err)?;
                chart
                    .draw_series(pts.iter().map(|(x, s)| {
                        ErrorBar::new_vertical(
                            *x,
                            (s.mean - s.std).max(0.0),
                            s.mean,
                            s.mean + s.std,
                            colour.stroke_width(2),
                            10,
                        )
                    }))
                    .map_err(err)?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .label_font((FONT, 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(err)?;
        }
        Ok(())
    })?)
}
