//! The sensors panel: every sensor's `vehicle_from_sensor` as x, y, z and roll, pitch, yaw with
//! drag values and nudge buttons; reset to initial; copy as text.

use glam::{DQuat, DVec3, EulerRot};

use super::state::Studio;
use crate::geometry::Rigid;

fn from_xyz_rpy(xyz: [f64; 3], rpy_deg: [f64; 3]) -> Rigid {
    let [r, p, y] = rpy_deg.map(f64::to_radians);
    Rigid::new(
        DQuat::from_euler(EulerRot::ZYX, y, p, r),
        DVec3::from_array(xyz),
    )
}

pub(crate) fn sensors_ui(studio: &mut Studio, ui: &mut egui::Ui) {
    ui.heading("Sensors");
    ui.label(format!("vehicle frame: {}", studio.current.vehicle_frame));
    ui.label("p_vehicle = vehicle_from_sensor · p_sensor");
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
            let Some(sensor) = studio.current.sensor(&name) else {
                continue;
            };
            let t = sensor.vehicle_from_sensor;
            let mut xyz = t.translation.to_array();
            let mut rpy = t.roll_pitch_yaw_rad().map(f64::to_degrees);
            let kind = sensor.kind.as_str();
            let mut changed = false;
            egui::CollapsingHeader::new(format!("{name} ({kind})"))
                .id_salt(&name)
                .show(ui, |ui| {
                    let (step_m, step_deg) = (studio.nudge_step_m, studio.nudge_step_deg);
                    egui::Grid::new(format!("grid-{name}"))
                        .num_columns(4)
                        .show(ui, |ui| {
                            for (label, v) in ["x m", "y m", "z m"].iter().zip(xyz.iter_mut()) {
                                ui.label(*label);
                                changed |= ui
                                    .add(egui::DragValue::new(v).speed(0.001).fixed_decimals(4))
                                    .changed();
                                if ui.small_button("−").clicked() {
                                    *v -= step_m;
                                    changed = true;
                                }
                                if ui.small_button("+").clicked() {
                                    *v += step_m;
                                    changed = true;
                                }
                                ui.end_row();
                            }
                            for (label, v) in
                                ["roll °", "pitch °", "yaw °"].iter().zip(rpy.iter_mut())
                            {
                                ui.label(*label);
                                changed |= ui
                                    .add(egui::DragValue::new(v).speed(0.01).fixed_decimals(3))
                                    .changed();
                                if ui.small_button("−").clicked() {
                                    *v -= step_deg;
                                    changed = true;
                                }
                                if ui.small_button("+").clicked() {
                                    *v += step_deg;
                                    changed = true;
                                }
                                ui.end_row();
                            }
                        });
                    ui.horizontal(|ui| {
                        if ui.button("reset to initial").clicked()
                            && let Some(init) = studio.initial.sensor(&name)
                        {
                            let init = init.vehicle_from_sensor;
                            studio.set_extrinsic(&name, init);
                        }
                        if ui
                            .button("copy")
                            .on_hover_text("translation_m and rotation_xyzw as YAML")
                            .clicked()
                        {
                            let q = t.rotation;
                            ui.ctx().copy_text(format!(
                                "translation_m: [{}, {}, {}]\nrotation_xyzw: [{}, {}, {}, {}]\n",
                                t.translation.x,
                                t.translation.y,
                                t.translation.z,
                                q.x,
                                q.y,
                                q.z,
                                q.w
                            ));
                        }
                    });
                });
            if changed {
                studio.set_extrinsic(&name, from_xyz_rpy(xyz, rpy));
            }
        }
    });
}
