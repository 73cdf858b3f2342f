//! A transform as text, for copy and paste between the studio and other tools.
//!
//! [`format_transform`] writes the native file's extrinsic fields (YAML). [`parse_transform`]
//! reads that, a whole `vehicle_from_sensor:` block, or plain numbers separated by spaces,
//! commas, brackets or newlines: 6 (x y z in m, roll pitch yaw in degrees, ZYX), 7 (x y z,
//! qx qy qz qw), 12 (a 3×4 row-major [R|t]) or 16 (a 4×4 row-major matrix). Rotations that are
//! not orthonormal are rejected rather than silently repaired.

use glam::{DMat3, DQuat, DVec3, EulerRot};

use super::file::ExtrinsicYaml;
use crate::error::ParseError;
use crate::geometry::Rigid;

/// The transform as the native file writes it (translation, quaternion, derived roll/pitch/yaw).
pub fn format_transform(t: Rigid) -> String {
    let q = t.rotation;
    let [r, p, y] = t.roll_pitch_yaw_rad().map(f64::to_degrees);
    format!(
        "translation_m: [{}, {}, {}]\nrotation_xyzw: [{}, {}, {}, {}]\n# roll, pitch, yaw (deg, ZYX): {r:.6}, {p:.6}, {y:.6}\n",
        t.translation.x, t.translation.y, t.translation.z, q.x, q.y, q.z, q.w
    )
}

pub fn parse_transform(text: &str) -> Result<Rigid, ParseError> {
    let text = text.trim();
    if text.is_empty() {
        return Err("nothing to parse".into());
    }
    if text.contains("translation_m") {
        let value: serde_yaml::Value =
            super::yaml::from_str(text).map_err(|e| format!("not valid YAML: {e}"))?;
        let inner = value.get("vehicle_from_sensor").cloned().unwrap_or(value);
        let e: ExtrinsicYaml = serde_yaml::from_value(inner)
            .map_err(|e| format!("needs translation_m and rotation_xyzw: {e}"))?;
        let [x, y, z, w] = e.rotation_xyzw;
        return from_quaternion(e.translation_m, [x, y, z, w]);
    }
    let numbers: Vec<f64> = text
        .split(|c: char| c.is_whitespace() || ",;[]()".contains(c))
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<f64>()
                .map_err(|_| format!("'{s}' is not a number"))
        })
        .collect::<Result<_, _>>()?;
    if numbers.iter().any(|v| !v.is_finite()) {
        return Err("numbers must be finite".into());
    }
    match numbers.len() {
        6 => {
            let [r, p, y] = [numbers[3], numbers[4], numbers[5]].map(f64::to_radians);
            Ok(Rigid::new(
                DQuat::from_euler(EulerRot::ZYX, y, p, r),
                DVec3::new(numbers[0], numbers[1], numbers[2]),
            ))
        }
        7 => from_quaternion(
            [numbers[0], numbers[1], numbers[2]],
            [numbers[3], numbers[4], numbers[5], numbers[6]],
        ),
        12 | 16 => rigid_from_matrix(&numbers),
        n => Err(format!(
            "{n} numbers: expected 6 (x y z roll pitch yaw°), 7 (x y z qx qy qz qw), 12 (3×4) or 16 (4×4)"
        ).into()),
    }
}

/// A rigid transform from a row-major 3×4 or 4×4 matrix (12 or 16 numbers), validated: finite,
/// last row `0 0 0 1`, rotation block orthonormal with determinant +1 (to 1e-4).
pub fn rigid_from_matrix(numbers: &[f64]) -> Result<Rigid, ParseError> {
    if numbers.len() != 12 && numbers.len() != 16 {
        return Err(format!(
            "{} numbers: a matrix needs 12 (3×4) or 16 (4×4)",
            numbers.len()
        )
        .into());
    }
    if numbers.iter().any(|v| !v.is_finite()) {
        return Err("numbers must be finite".into());
    }
    let m = |r: usize, c: usize| numbers[r * 4 + c];
    if numbers.len() == 16
        && ((m(3, 0).abs() + m(3, 1).abs() + m(3, 2).abs()) > 1e-6 || (m(3, 3) - 1.0).abs() > 1e-6)
    {
        return Err("the last row of a 4×4 rigid transform must be 0 0 0 1".into());
    }
    let rot = DMat3::from_cols(
        DVec3::new(m(0, 0), m(1, 0), m(2, 0)),
        DVec3::new(m(0, 1), m(1, 1), m(2, 1)),
        DVec3::new(m(0, 2), m(1, 2), m(2, 2)),
    );
    let err = (rot.transpose() * rot - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    if err > 1e-4 || rot.determinant() < 0.0 {
        return Err(format!(
            "the rotation part is not a rotation (orthonormality error {err:.1e})"
        )
        .into());
    }
    Ok(Rigid::new(
        DQuat::from_mat3(&rot).normalize(),
        DVec3::new(m(0, 3), m(1, 3), m(2, 3)),
    ))
}

fn from_quaternion(t: [f64; 3], xyzw: [f64; 4]) -> Result<Rigid, ParseError> {
    let q = DQuat::from_xyzw(xyzw[0], xyzw[1], xyzw[2], xyzw[3]);
    let n = q.length();
    if !(0.9..=1.1).contains(&n) {
        return Err(format!("the quaternion's norm is {n:.3}, not 1").into());
    }
    Ok(Rigid::new(q.normalize(), DVec3::from_array(t)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Rigid {
        Rigid::new(
            DQuat::from_euler(EulerRot::ZYX, 0.3, -0.1, 0.05),
            DVec3::new(1.5, -0.2, 1.8),
        )
    }

    fn close(a: Rigid, b: Rigid) -> bool {
        let (r, t) = a.difference(b);
        r < 1e-9 && t < 1e-9
    }

    #[test]
    fn copied_text_pastes_back_to_the_same_transform() {
        let t = sample();
        assert!(close(parse_transform(&format_transform(t)).unwrap(), t));
        let block = format!(
            "vehicle_from_sensor:\n  {}",
            format_transform(t).replace('\n', "\n  ")
        );
        assert!(close(parse_transform(&block).unwrap(), t));
    }

    #[test]
    fn plain_numbers_in_every_layout() {
        let t = sample();
        let [r, p, y] = t.roll_pitch_yaw_rad().map(f64::to_degrees);
        let (x, yy, z) = (t.translation.x, t.translation.y, t.translation.z);
        let six = format!("{x} {yy} {z} {r} {p} {y}");
        assert!(close(parse_transform(&six).unwrap(), t));
        let q = t.rotation;
        let seven = format!("[{x}, {yy}, {z}, {}, {}, {}, {}]", q.x, q.y, q.z, q.w);
        assert!(close(parse_transform(&seven).unwrap(), t));
        let m = t.to_mat4();
        let rows: Vec<String> = (0..4)
            .map(|r| {
                (0..4)
                    .map(|c| m.col(c)[r].to_string())
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect();
        assert!(close(parse_transform(&rows.join("\n")).unwrap(), t));
        assert!(close(parse_transform(&rows[..3].join("\n")).unwrap(), t));
    }

    #[test]
    fn bad_text_is_a_clear_error() {
        assert!(
            parse_transform("")
                .unwrap_err()
                .to_string()
                .contains("nothing")
        );
        assert!(
            parse_transform("1 2 3")
                .unwrap_err()
                .to_string()
                .contains("3 numbers")
        );
        assert!(
            parse_transform("1 2 x 4 5 6")
                .unwrap_err()
                .to_string()
                .contains("'x'")
        );
        assert!(
            parse_transform("0 0 0 0 0 0 2")
                .unwrap_err()
                .to_string()
                .contains("norm")
        );
        let sheared = "1 0.5 0 0  0 1 0 0  0 0 1 0  0 0 0 1";
        assert!(
            parse_transform(sheared)
                .unwrap_err()
                .to_string()
                .contains("not a rotation")
        );
        assert!(parse_transform("translation_m: [1, 2]\n").is_err());
    }
}
