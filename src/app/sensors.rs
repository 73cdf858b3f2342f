//! The sensors panel: the frame tree, then every sensor's `vehicle_from_sensor` as x, y, z and
//! roll, pitch, yaw with drag values, nudge buttons, axis locks (locked axes ignore edits and
//! optimisers), reset to initial, and copy / paste as text ([`crate::calib::transform_text`]).

use std::collections::BTreeMap;

use glam::{DQuat, DVec3, EulerRot};

use super::state::Studio;
use crate::calib::transform_text::{format_transform, parse_transform};
use crate::geometry::Rigid;
use crate::log::Drive;

fn from_xyz_rpy(xyz: [f64; 3], rpy_deg: [f64; 3]) -> Rigid {
    let [r, p, y] = rpy_deg.map(f64::to_radians);
    Rigid::new(
        DQuat::from_euler(EulerRot::ZYX, y, p, r),
        DVec3::from_array(xyz),
    )
}

/// The TF tree as parent → children (static edges solid, dynamic ones marked).
fn frame_tree_ui(drive: &Drive, ui: &mut egui::Ui) {
    let mut children: BTreeMap<String, Vec<(String, bool)>> = BTreeMap::new();
    let mut has_parent = std::collections::BTreeSet::new();
    for (child, (parent, _)) in &drive.tf.static_edges {
        children
            .entry(parent.clone())
            .or_default()
            .push((child.clone(), false));
        has_parent.insert(child.clone());
    }
    for (parent, child) in drive.tf.dynamic_edges.keys() {
        children
            .entry(parent.clone())
            .or_default()
            .push((child.clone(), true));
        has_parent.insert(child.clone());
    }
    let roots: Vec<String> = drive
        .tf
        .frames()
        .into_iter()
        .filter(|f| !has_parent.contains(f))
        .collect();
    fn node(
        ui: &mut egui::Ui,
        name: &str,
        dynamic: bool,
        children: &BTreeMap<String, Vec<(String, bool)>>,
        depth: usize,
    ) {
        let label = if dynamic {
            format!("{name}  (moving: /tf)")
        } else {
            name.to_string()
        };
        match children.get(name) {
            Some(kids) if depth < 16 => {
                egui::CollapsingHeader::new(label)
                    .id_salt(("tf", name))
                    .default_open(true)
                    .show(ui, |ui| {
                        for (k, d) in kids {
                            node(ui, k, *d, children, depth + 1);
                        }
                    });
            }
            _ => {
                ui.label(format!("• {label}"));
            }
        }
    }
    egui::CollapsingHeader::new("Frame tree")
        .default_open(false)
        .show(ui, |ui| {
            if roots.is_empty() {
                ui.weak("(no /tf or /tf_static in this log)");
            }
            for r in &roots {
                node(ui, r, false, &children, 0);
            }
            ui.weak(format!("trajectory: {}", drive.trajectory_source));
        });
}

pub(crate) fn sensors_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    ui.heading("Sensors");
    ui.label(format!("vehicle frame: {}", studio.current.vehicle_frame));
    ui.label("p_vehicle = vehicle_from_sensor · p_sensor");
    if let Some(drive) = studio.drive.clone() {
        frame_tree_ui(&drive, ui);
    }
    ui.horizontal(|ui| {
        ui.label("nudge");
        ui.add(
            egui::DragValue::new(&mut studio.nudge_step_m)
                .speed(0.001)
                .range(0.0001..=1.0)
                .suffix(" m"),
        );
        ui.add(
            egui::DragValue::new(&mut studio.nudge_step_deg)
                .speed(0.01)
                .range(0.001..=10.0)
                .suffix(" °"),
        );
    });
    ui.separator();
    let names: Vec<String> = studio
        .current
        .sensors
        .iter()
        .map(|s| s.name.clone())
        .collect();
    egui::ScrollArea::vertical().show(ui, |ui| {
        for name in names {
            sensor_ui(studio, ui, &name);
        }
    });
}

fn sensor_ui(studio: &mut Studio, ui: &mut egui::Ui, name: &str) {
    let Some(sensor) = studio.current.sensor(name) else {
        return;
    };
    let t = sensor.vehicle_from_sensor;
    let mut xyz = t.translation.to_array();
    let mut rpy = t.roll_pitch_yaw_rad().map(f64::to_degrees);
    let kind = sensor.kind.as_str();
    let mut locks = studio.locks.get(name).copied().unwrap_or_default();
    let mut changed = false;
    let mut dragging = false;
    let running = studio.optimiser.run.is_some();
    let locked = locks.iter().any(|&l| l);
    let title = if locked {
        format!("{name} ({kind}) [locked]")
    } else {
        format!("{name} ({kind})")
    };
    egui::CollapsingHeader::new(title)
        .id_salt(name)
        .show(ui, |ui| {
            let (step_m, step_deg) = (studio.nudge_step_m, studio.nudge_step_deg);
            egui::Grid::new(format!("grid-{name}"))
                .num_columns(5)
                .show(ui, |ui| {
                    let rows = ["x m", "y m", "z m", "roll °", "pitch °", "yaw °"];
                    let offset_m = crate::calib::file::MAX_SENSOR_OFFSET_M;
                    for (axis, label) in rows.iter().enumerate() {
                        let (v, step, speed, decimals, range) = if axis < 3 {
                            (&mut xyz[axis], step_m, 0.001, 4, -offset_m..=offset_m)
                        } else {
                            (&mut rpy[axis - 3], step_deg, 0.01, 3, -360.0..=360.0)
                        };
                        ui.label(*label);
                        // While an optimiser run owns the rig, its fields show it live.
                        let free = !locks[axis] && !running;
                        let field = ui.add_enabled(
                            free,
                            egui::DragValue::new(v)
                                .speed(speed)
                                .range(range)
                                // Typed values are clamped; a log's own value beyond the range
                                // is shown as it is, not changed by being drawn.
                                .clamp_existing_to_range(false)
                                .fixed_decimals(decimals),
                        );
                        changed |= field.changed();
                        dragging |= field.dragged();
                        if ui
                            .add_enabled(free, egui::Button::new("−").small())
                            .clicked()
                        {
                            *v -= step;
                            changed = true;
                        }
                        if ui
                            .add_enabled(free, egui::Button::new("+").small())
                            .clicked()
                        {
                            *v += step;
                            changed = true;
                        }
                        ui.checkbox(&mut locks[axis], "lock")
                            .on_hover_text("locked: edits and optimisers leave this axis alone");
                        ui.end_row();
                    }
                });
            ui.horizontal(|ui| {
                if ui.button("reset to initial").clicked()
                    && let Some(init) = studio.initial.sensor(name)
                {
                    let init = init.vehicle_from_sensor;
                    studio.set_extrinsic(name, init);
                }
                if ui
                    .button("copy")
                    .on_hover_text("translation_m and rotation_xyzw as YAML")
                    .clicked()
                {
                    ui.ctx().copy_text(format_transform(t));
                    studio
                        .status
                        .push(format!("copied {name}'s vehicle_from_sensor"));
                }
            });
            ui.horizontal(|ui| {
                ui.add(
                    egui::TextEdit::singleline(&mut studio.paste_text)
                        .hint_text("paste: YAML, x y z r p y°, quaternion, 3×4 or 4×4")
                        .desired_width(220.0),
                );
                if ui
                    .button("apply")
                    .on_hover_text("set vehicle_from_sensor from the text")
                    .clicked()
                {
                    match parse_transform(&studio.paste_text) {
                        Ok(p) => {
                            studio.set_extrinsic(name, p);
                            studio
                                .status
                                .push(format!("pasted {name}'s vehicle_from_sensor"));
                        }
                        Err(e) => studio.status.push(format!("error: paste into {name}: {e}")),
                    }
                }
            });
        });
    if locks.iter().any(|&l| l) {
        studio.locks.insert(name.to_string(), locks);
    } else {
        studio.locks.remove(name);
    }
    // A drag is one edit: the first frame that changes a value adds an undo entry, the later
    // frames of the same drag amend it.
    let drag_open = studio.drag_undo_open.as_deref() == Some(name);
    if changed {
        let next = from_xyz_rpy(xyz, rpy);
        if dragging && drag_open {
            studio.amend_extrinsic(name, next);
        } else if studio.set_extrinsic(name, next) && dragging {
            studio.drag_undo_open = Some(name.to_string());
        }
    }
    if !dragging && drag_open {
        studio.drag_undo_open = None;
    }
}
