//! The bench's tables: Markdown in the paper's layouts (Tables A7, A8, A10, A1; means ± standard
//! deviations over seeds), a CSV with one row per case and sensor, and the whole report as JSON.

use std::fmt::Write as _;

use serde::Serialize;

use super::case::{CaseResult, Errors};
use super::suite::{Case, Protocol, Suite};

/// A finished suite.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub suite: String,
    pub machine: String,
    pub date: String,
    pub total_secs: f64,
    pub cases: Vec<Case>,
    /// One per distinct run ([`Case::key`]).
    pub results: Vec<CaseResult>,
}

/// Mean, sample standard deviation and count.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
    pub n: usize,
}

pub fn stat(values: &[f64]) -> Option<Stat> {
    if values.is_empty() {
        return None;
    }
    let n = values.len();
    let mean = values.iter().sum::<f64>() / n as f64;
    let var = if n > 1 {
        values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64
    } else {
        0.0
    };
    Some(Stat {
        mean,
        std: var.sqrt(),
        n,
    })
}

/// `mean ± std unit` (just the mean for one value), or "—".
fn show(s: Option<Stat>, scale: f64, decimals: usize, unit: &str) -> String {
    match s {
        None => "—".into(),
        Some(s) if s.n == 1 => format!("{:.*}{unit}", decimals, s.mean * scale),
        Some(s) => format!(
            "{:.*} ± {:.*}{unit}",
            decimals,
            s.mean * scale,
            decimals,
            s.std * scale
        ),
    }
}

/// The four mean errors over a group of runs (failed runs left out).
pub struct GroupStats {
    pub camera_rotation_deg: Option<Stat>,
    pub camera_translation_cm: Option<Stat>,
    pub lidar_rotation_deg: Option<Stat>,
    pub lidar_translation_cm: Option<Stat>,
    pub runs: usize,
    pub failed: usize,
}

pub fn group_stats(results: &[&CaseResult], pick: impl Fn(&CaseResult) -> Errors) -> GroupStats {
    let ok: Vec<Errors> = results
        .iter()
        .filter(|r| r.error.is_none())
        .map(|r| pick(r))
        .collect();
    let field = |f: fn(&Errors) -> Option<f64>| stat(&ok.iter().filter_map(f).collect::<Vec<_>>());
    GroupStats {
        camera_rotation_deg: field(|e| e.camera_rotation_deg),
        camera_translation_cm: field(|e| e.camera_translation_cm),
        lidar_rotation_deg: field(|e| e.lidar_rotation_deg),
        lidar_translation_cm: field(|e| e.lidar_translation_cm),
        runs: ok.len(),
        failed: results.len() - ok.len(),
    }
}

impl BenchReport {
    pub fn result(&self, case: &Case) -> Option<&CaseResult> {
        let key = case.key();
        self.results.iter().find(|r| r.key == key)
    }

    /// Results of `protocol`, grouped by (row, method) in suite order.
    fn groups(&self, protocol: Protocol) -> Vec<(String, String, Vec<&CaseResult>)> {
        let mut out: Vec<(String, String, Vec<&CaseResult>)> = Vec::new();
        for case in self.cases.iter().filter(|c| c.protocol == protocol) {
            let Some(r) = self.result(case) else {
                continue;
            };
            let method = case.method.label().to_string();
            match out
                .iter_mut()
                .find(|(row, m, _)| *row == case.row && *m == method)
            {
                Some((_, _, rs)) => rs.push(r),
                None => out.push((case.row.clone(), method, vec![r])),
            }
        }
        out
    }

    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "# rigcal bench --suite {}\n\n{}; {}; {:.0} s in all. Errors after root-sensor \
             alignment (method.md §13): the mean over the optimised cameras and over the \
             optimised LiDARs other than the root; mean ± standard deviation over seeds.\n",
            self.suite, self.machine, self.date, self.total_secs
        );
        self.perturbation_table(&mut md);
        self.metre_table(&mut md, Protocol::Trajectory, "Trajectory");
        self.metre_table(&mut md, Protocol::Featureless, "Scene");
        self.metre_table(&mut md, Protocol::Sensors, "Sensors");
        self.metre_table(&mut md, Protocol::Ablation, "Variant");
        self.metre_table(&mut md, Protocol::Correspondence, "Correspondence loss");
        self.pandaset_table(&mut md);
        self.photometric_table(&mut md);
        self.runtime_table(&mut md);
        let failed: Vec<_> = self.results.iter().filter(|r| r.error.is_some()).collect();
        if !failed.is_empty() {
            let _ = writeln!(md, "## Failed runs\n");
            for r in failed {
                let _ = writeln!(
                    md,
                    "- {} on {} (seed {}): {}",
                    r.method,
                    r.drive,
                    r.seed,
                    r.error.as_deref().unwrap_or("")
                );
            }
            md.push('\n');
        }
        md
    }

    fn perturbation_table(&self, md: &mut String) {
        let groups = self.groups(Protocol::Perturbation);
        if groups.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "## {}\n\n| initial error | method | camera rotation | camera translation | LiDAR rotation | LiDAR translation | runs |\n|---|---|---|---|---|---|---|",
            Protocol::Perturbation.title()
        );
        for (row, method, rs) in groups {
            let g = group_stats(&rs, |r| r.result);
            let _ = writeln!(
                md,
                "| {row} | {method} | {} | {} | {} | {} | {}{} |",
                show(g.camera_rotation_deg, 1.0, 2, "°"),
                show(g.camera_translation_cm, 1.0, 1, " cm"),
                show(g.lidar_rotation_deg, 1.0, 2, "°"),
                show(g.lidar_translation_cm, 1.0, 1, " cm"),
                g.runs,
                failed_note(g.failed)
            );
        }
        md.push('\n');
    }

    /// Rotation in degrees, translation in metres (the paper's A8 / A10 units), with the
    /// initial errors beside the results.
    fn metre_table(&self, md: &mut String, protocol: Protocol, first: &str) {
        let groups = self.groups(protocol);
        if groups.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "## {}\n\n| {first} | method | camera rotation (°) | camera translation (m) | LiDAR rotation (°) | LiDAR translation (m) | initial camera / LiDAR | optimisation |\n|---|---|---|---|---|---|---|---|",
            protocol.title()
        );
        for (row, method, rs) in groups {
            let g = group_stats(&rs, |r| r.result);
            let i = group_stats(&rs, |r| r.initial);
            let initial = format!(
                "{} {} / {} {}",
                show(i.camera_rotation_deg, 1.0, 2, "°"),
                show(i.camera_translation_cm, 0.01, 3, " m"),
                show(i.lidar_rotation_deg, 1.0, 2, "°"),
                show(i.lidar_translation_cm, 0.01, 3, " m"),
            );
            let ok: Vec<f64> = rs
                .iter()
                .filter(|r| r.error.is_none())
                .map(|r| r.run_secs)
                .collect();
            let _ = writeln!(
                md,
                "| {row} | {method} | {} | {} | {} | {} | {initial}{} | {} |",
                show(g.camera_rotation_deg, 1.0, 3, ""),
                show(g.camera_translation_cm, 0.01, 3, ""),
                show(g.lidar_rotation_deg, 1.0, 3, ""),
                show(g.lidar_translation_cm, 0.01, 3, ""),
                failed_note(g.failed),
                show(stat(&ok), 1.0, 1, " s")
            );
        }
        if protocol == Protocol::Sensors {
            let _ = writeln!(
                md,
                "\nCamera-only: no LiDAR ray is rendered, no geometry initialisation, LiDAR \
                 extrinsics untouched; the LiDAR returns only place the occupancy grid camera \
                 rays are sampled in. Its errors are relative to the first camera (the root)."
            );
        }
        md.push('\n');
    }

    fn pandaset_table(&self, md: &mut String) {
        let cases: Vec<_> = self
            .cases
            .iter()
            .filter(|c| c.protocol == Protocol::PandaSet)
            .filter_map(|c| self.result(c))
            .collect();
        if cases.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "## {}\n\n| method | sensor | initial rotation | initial translation | rotation | translation |\n|---|---|---|---|---|---|",
            Protocol::PandaSet.title()
        );
        for r in cases {
            if let Some(e) = &r.error {
                let _ = writeln!(md, "| {} | failed: {e} | | | | |", r.method);
                continue;
            }
            for s in r.sensors.iter().filter(|s| s.optimised) {
                let _ = writeln!(
                    md,
                    "| {} | {} ({} ↔ root {}) | {:.3}° | {:.1} cm | {:.3}° | {:.1} cm |",
                    r.method,
                    s.sensor,
                    s.kind,
                    r.root,
                    s.initial_rotation_deg,
                    s.initial_translation_cm,
                    s.final_rotation_deg,
                    s.final_translation_cm
                );
            }
            let cameras: Vec<_> = r
                .sensors
                .iter()
                .filter(|s| s.optimised && s.kind == "camera")
                .collect();
            if !cameras.is_empty() {
                let better = cameras
                    .iter()
                    .filter(|s| {
                        s.final_rotation_deg < s.initial_rotation_deg
                            && s.final_translation_cm < s.initial_translation_cm
                    })
                    .count();
                let _ = writeln!(
                    md,
                    "| {} | cameras below their initial rotation and translation error | {better} of {} | | | |",
                    r.method,
                    cameras.len()
                );
            }
        }
        md.push('\n');
    }

    fn photometric_table(&self, md: &mut String) {
        let rows: Vec<_> = self
            .cases
            .iter()
            .filter_map(|c| Some((c, self.result(c)?.photometric.as_ref()?)))
            .collect();
        if rows.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "## Photometric consistency of a held-out frame (fitted scene)\n\n| protocol | row | seed | camera | frame | size | PSNR | SSIM |\n|---|---|---|---|---|---|---|---|"
        );
        let mut seen = std::collections::HashSet::new();
        for (case, p) in rows {
            if !seen.insert(case.key()) {
                continue;
            }
            let _ = writeln!(
                md,
                "| {:?} | {} | {} | {} | {} | {}×{} | {:.2} dB | {:.3} |",
                case.protocol,
                case.row,
                case.seed,
                p.camera,
                p.frame,
                p.width,
                p.height,
                p.psnr_db,
                p.ssim
            );
        }
        md.push('\n');
    }

    /// Table A1's layout: run time per method.
    fn runtime_table(&self, md: &mut String) {
        let mut methods: Vec<(String, Vec<&CaseResult>)> = Vec::new();
        for r in self.results.iter().filter(|r| r.error.is_none()) {
            match methods.iter_mut().find(|(m, _)| *m == r.method) {
                Some((_, rs)) => rs.push(r),
                None => methods.push((r.method.clone(), vec![r])),
            }
        }
        if methods.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "## Run time (Table A1 layout)\n\n| method | runs | preparation (mean) | optimisation (mean) | steps | steps/s |\n|---|---|---|---|---|---|"
        );
        for (method, rs) in methods {
            let n = rs.len() as f64;
            let prepare = rs.iter().map(|r| r.prepare_secs).sum::<f64>() / n;
            let run = rs.iter().map(|r| r.run_secs).sum::<f64>() / n;
            let steps = rs.iter().map(|r| r.steps).sum::<usize>() as f64 / n;
            let _ = writeln!(
                md,
                "| {method} | {} | {prepare:.1} s | {run:.1} s | {steps:.0} | {:.2} |",
                rs.len(),
                steps / run.max(1e-9)
            );
        }
        md.push('\n');
    }

    /// One row per case and sensor.
    pub fn to_csv(&self) -> String {
        let mut csv = String::from(
            "protocol,row,method,drive,perturb_deg,perturb_cm,seed,sensor,kind,optimised,\
             initial_rotation_deg,initial_translation_cm,final_rotation_deg,final_translation_cm,\
             steps,prepare_s,run_s,psnr_db,ssim,error\n",
        );
        for case in &self.cases {
            let Some(r) = self.result(case) else {
                continue;
            };
            let (psnr, ssim) = r
                .photometric
                .as_ref()
                .map_or((String::new(), String::new()), |p| {
                    (format!("{:.3}", p.psnr_db), format!("{:.4}", p.ssim))
                });
            let prefix = format!(
                "{:?},{},{},{},{},{},{}",
                case.protocol,
                csv_field(&case.row),
                csv_field(case.method.label()),
                csv_field(&r.drive),
                case.perturb_deg,
                case.perturb_cm,
                case.seed
            );
            let suffix = format!(
                "{},{:.2},{:.2},{psnr},{ssim},{}",
                r.steps,
                r.prepare_secs,
                r.run_secs,
                csv_field(r.error.as_deref().unwrap_or(""))
            );
            if r.sensors.is_empty() {
                let _ = writeln!(csv, "{prefix},,,,,,,,{suffix}");
            }
            for s in &r.sensors {
                let _ = writeln!(
                    csv,
                    "{prefix},{},{},{},{:.5},{:.4},{:.5},{:.4},{suffix}",
                    csv_field(&s.sensor),
                    s.kind,
                    s.optimised,
                    s.initial_rotation_deg,
                    s.initial_translation_cm,
                    s.final_rotation_deg,
                    s.final_translation_cm
                );
            }
        }
        csv
    }
}

fn failed_note(failed: usize) -> String {
    if failed == 0 {
        String::new()
    } else {
        format!(" ({failed} failed)")
    }
}

/// Quote a CSV field when it needs it.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// The report of `suite` with `results` (for callers that ran the cases themselves).
pub fn report(
    suite: &Suite,
    results: Vec<CaseResult>,
    machine: String,
    date: String,
    total_secs: f64,
) -> BenchReport {
    BenchReport {
        suite: suite.name.clone(),
        machine,
        date,
        total_secs,
        cases: suite.cases.clone(),
        results,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_are_sample_mean_and_deviation() {
        let s = stat(&[1.0, 2.0, 3.0]).unwrap_or(Stat {
            mean: 0.0,
            std: 0.0,
            n: 0,
        });
        assert_eq!((s.mean, s.n), (2.0, 3));
        assert!((s.std - 1.0).abs() < 1e-12);
        assert_eq!(stat(&[]), None);
        assert_eq!(show(stat(&[0.5]), 1.0, 2, "°"), "0.50°");
        assert_eq!(show(stat(&[10.0, 30.0]), 0.01, 3, " m"), "0.200 ± 0.141 m");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
    }
}
