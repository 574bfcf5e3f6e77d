//! Small 3-vector and rotation helpers for the pose-sensing steps (docs/marvel.md
//! section 1). Plain arrays keep this crate free of a linear-algebra
//! dependency: everything here is 3x3.
//!
//! Conventions (docs/marvel.md section 1): world frame W z up; body frame B x
//! forward, y left, z up; a rotation `R = world_R_body` maps body vectors to
//! world vectors, `p_W = R p_B + t`. Matrices are row-major, `m[row][col]`.
//! Direction `u(az, el) = (cos el cos az, cos el sin az, sin el)`; yaw is
//! `atan2(R[1][0], R[0][0])`, and with the ZYX (yaw-pitch-roll) factorisation
//! `R = Rz(yaw) Ry(pitch) Rx(roll)`.

/// A 3-vector (m, m/s, rad/s, or unitless, as each caller says).
pub type Vec3 = [f64; 3];
/// A row-major 3x3 matrix, `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

/// The identity rotation.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub fn dot(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn norm(a: &Vec3) -> f64 {
    dot(a, a).sqrt()
}

pub fn sub(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn add(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn scale(a: &Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a / |a|`, or `None` for a zero or non-finite vector.
pub fn normalize(a: &Vec3) -> Option<Vec3> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

/// `m v`.
pub fn mat_vec(m: &Mat3, v: &Vec3) -> Vec3 {
    [dot(&m[0], v), dot(&m[1], v), dot(&m[2], v)]
}

/// `a b`.
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

pub fn transpose(m: &Mat3) -> Mat3 {
    [[m[0][0], m[1][0], m[2][0]], [m[0][1], m[1][1], m[2][1]], [m[0][2], m[1][2], m[2][2]]]
}

/// Rotation about +x by `angle` rad (right-handed).
pub fn rotation_x(angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
}

/// Rotation about +y by `angle` rad.
pub fn rotation_y(angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}

/// Rotation about +z by `angle` rad.
pub fn rotation_z(angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

/// The roll/pitch part of the attitude, `R_rp = Ry(pitch) Rx(roll)`, so
/// that `R = Rz(yaw) R_rp` (ZYX Euler angles, rad).
pub fn roll_pitch_matrix(roll: f64, pitch: f64) -> Mat3 {
    mat_mul(&rotation_y(pitch), &rotation_x(roll))
}

/// Yaw of `R = world_R_body`: the heading of body x about +z,
/// `atan2(R[1][0], R[0][0])` (docs/marvel.md section 1), rad in (-pi, pi].
pub fn yaw_of(r: &Mat3) -> f64 {
    r[1][0].atan2(r[0][0])
}

/// Splits `R` into its yaw and the yaw-free part: `R = Rz(yaw) R_rp` with
/// `R_rp = Rz(-yaw) R` (whose own yaw is 0). This is how a tracker turns a
/// full attitude (or the IMU's gravity-levelled one) into the roll/pitch
/// input of [`super::solve_yaw`].
pub fn split_yaw(r: &Mat3) -> (f64, Mat3) {
    let yaw = yaw_of(r);
    (yaw, mat_mul(&rotation_z(-yaw), r))
}

/// `u(az, el) = (cos el cos az, cos el sin az, sin el)`, rad.
pub fn direction(azimuth: f64, elevation: f64) -> Vec3 {
    let (sa, ca) = azimuth.sin_cos();
    let (se, ce) = elevation.sin_cos();
    [ce * ca, ce * sa, se]
}

/// `(az, el)` of a direction (need not be unit length), rad; az in
/// (-pi, pi], el in [-pi/2, pi/2].
pub fn azimuth_elevation(u: &Vec3) -> (f64, f64) {
    let horizontal = (u[0] * u[0] + u[1] * u[1]).sqrt();
    (u[1].atan2(u[0]), u[2].atan2(horizontal))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_split_round_trips_and_direction_inverts() {
        for &(roll, pitch, yaw) in &[(0.1, -0.2, 2.5), (-0.3, 0.25, -1.0), (0.0, 0.0, 3.0)] {
            let r = mat_mul(&rotation_z(yaw), &roll_pitch_matrix(roll, pitch));
            let (y, rp) = split_yaw(&r);
            assert!((y - yaw).abs() < 1e-12);
            let back = mat_mul(&rotation_z(y), &rp);
            for i in 0..3 {
                for j in 0..3 {
                    assert!((back[i][j] - r[i][j]).abs() < 1e-12);
                    assert!((rp[i][j] - roll_pitch_matrix(roll, pitch)[i][j]).abs() < 1e-12);
                }
            }
        }
        let (az, el) = azimuth_elevation(&direction(2.0, -0.4));
        assert!((az - 2.0).abs() < 1e-12 && (el + 0.4).abs() < 1e-12);
    }
}
