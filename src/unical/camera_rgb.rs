//! The camera colour term (main Eq. 3, method.md §4 and §8) for a batch of rays, with gradients
//! for the scene, the appearance decoders, the camera's exposure mapping and its pose.
//!
//! A ray leaves camera k through a pixel at its row's time (the frame's, for a global
//! shutter): `o = P(t)·t_k`, `d = R_P R_k u`
//! with `u` the camera model's unit ray. Samples every 10 cm in occupied space are composited
//! front to back into a feature `F = Σ w_i f_i` (feature rendering, §4(a)), stopping once the
//! transmittance is negligible; what is left (`T = 1 − A`) sees the sky, a feature from a small
//! MLP on the view direction. The colour decoder (3 layers on the feature and a degree-3
//! spherical-harmonics encoding of the view direction, sigmoid output) gives `C`, the camera's
//! per-channel affine exposure mapping `Ĉ = a ⊙ C + b` absorbs gain and tone, and the loss is
//! the mean of `‖Ĉ − C_gt‖²`.
//!
//! Backward: exposure → decoder (→ ∂L/∂F and ∂L/∂SH) → sky MLP and accumulation → compositing
//! → field → ∂L/∂x_i → ∂L/∂o, ∂L/∂d (plus the view direction's SH Jacobian) → pose.

use glam::DVec3;

use super::background::Background;
use super::composite::{Opacity, OpacityModel, Upstream, composite, composite_backward};
use super::field::{FieldSample, SceneField};
use super::hash_grid::GradSink;
use super::mlp::{Mlp, MlpGrad};
use super::pose::{PoseGrad, PoseParams};
use crate::geometry::Rigid;

/// Samples stop once this little light gets through.
const MIN_TRANSMITTANCE: f32 = 1e-3;
/// Samples per batch when a camera ray is marched (the last batch may run past the point where
/// the light runs out: those samples are dropped).
const MARCH_CHUNK: usize = 16;
/// Size of the view-direction encoding.
pub const SH_DIM: usize = 16;

/// Real spherical harmonics of degree 0 to 3 of a unit direction.
pub fn sh_encoding(d: DVec3) -> [f64; SH_DIM] {
    let (x, y, z) = (d.x, d.y, d.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    [
        0.282_094_791_773_878_1,
        0.488_602_511_902_919_9 * y,
        0.488_602_511_902_919_9 * z,
        0.488_602_511_902_919_9 * x,
        1.092_548_430_592_079_2 * x * y,
        1.092_548_430_592_079_2 * y * z,
        0.946_174_695_757_560_1 * zz - 0.315_391_565_252_52,
        1.092_548_430_592_079_2 * x * z,
        0.546_274_215_296_039_6 * (xx - yy),
        0.590_043_589_926_643_5 * y * (3.0 * xx - yy),
        2.890_611_442_640_554 * x * y * z,
        0.457_045_799_464_465_8 * y * (5.0 * zz - 1.0),
        0.373_176_332_590_115_4 * z * (5.0 * zz - 3.0),
        0.457_045_799_464_465_8 * x * (5.0 * zz - 1.0),
        1.445_305_721_320_277 * z * (xx - yy),
        0.590_043_589_926_643_5 * x * (xx - 3.0 * yy),
    ]
}

/// `Σ_j g_j ∂SH_j/∂d` by central differences of the (polynomial) encoding in f64: exact to
/// ~1e-10, and six evaluations of 16 polynomials are nothing next to the field queries.
pub(super) fn sh_backward(d: DVec3, g: &[f32]) -> DVec3 {
    let h = 1e-6;
    let mut out = DVec3::ZERO;
    for axis in 0..3 {
        let mut e = DVec3::ZERO;
        e[axis] = h;
        let (up, down) = (sh_encoding(d + e), sh_encoding(d - e));
        out[axis] = (0..SH_DIM)
            .map(|j| g[j] as f64 * (up[j] - down[j]) / (2.0 * h))
            .sum();
    }
    out
}

/// The decoders shared by every camera: colour from (feature, SH) and the sky's feature.
#[derive(Clone, Debug)]
pub struct Appearance {
    pub colour: Mlp,
    pub sky: Mlp,
    /// Whether the colour decoder sees the view direction (the paper's decoder does). Without
    /// it surfaces are Lambertian: two cameras that disagree about a point cannot both be
    /// explained by a colour that changes with the direction it is seen from (the sky still
    /// depends on the direction).
    pub view_dependent: bool,
}

impl Appearance {
    /// The paper's colour decoder (3 layers, 64 wide) and a 2-layer sky MLP.
    pub fn new(feature_dim: usize, seed: u64) -> Self {
        Self {
            colour: Mlp::new(&[feature_dim + SH_DIM, 64, 64, 3], seed ^ 0xC01),
            sky: Mlp::new(&[SH_DIM, 32, feature_dim], seed ^ 0x5C7),
            view_dependent: true,
        }
    }
}

/// Per-camera affine exposure mapping `Ĉ = scale ⊙ C + offset` (§4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExposureMap {
    pub scale: [f32; 3],
    pub offset: [f32; 3],
}

impl Default for ExposureMap {
    fn default() -> Self {
        Self {
            scale: [1.0; 3],
            offset: [0.0; 3],
        }
    }
}

/// One camera ray ready to render.
#[derive(Clone, Debug)]
pub struct ColourRay {
    /// `world_from_vehicle` when the pixel's row was exposed (the frame's time for a global
    /// shutter).
    pub world_from_vehicle: Rigid,
    /// Unit direction in the camera frame.
    pub dir_in_sensor: DVec3,
    /// Observed colour in [0, 1].
    pub target: [f32; 3],
    /// Sample distances along the ray in the scene box (may be empty).
    pub taus_m: Vec<f32>,
    /// Sample distances in the background beyond it (empty without a background model).
    pub background_taus_m: Vec<f32>,
}

/// Loss and gradients of one batch.
#[derive(Debug)]
pub struct ColourStep {
    pub loss: f64,
    pub geo: MlpGrad,
    pub colour: MlpGrad,
    pub sky: MlpGrad,
    /// The background MLP's gradients (empty without a background).
    pub background_mlp: MlpGrad,
    pub beta_grad: f64,
    pub pose: PoseGrad,
    /// ∂L/∂scale then ∂L/∂offset.
    pub exposure: [f64; 6],
}

pub(super) fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Query the samples `o + τ d` front to back until the ray is opaque (`transmittance` below
/// [`MIN_TRANSMITTANCE`], carried over between calls); appends their opacities to `alphas` and
/// where their weights sit to `at`. Camera and surface-alignment rays both march this way.
pub(super) fn march(
    query: &dyn Fn(&[DVec3]) -> Vec<FieldSample>,
    (o, d): (DVec3, DVec3),
    taus_m: &[f32],
    opacity: Opacity,
    (alphas, at): (&mut Vec<f32>, &mut Vec<f32>),
    transmittance: &mut f32,
) -> Vec<FieldSample> {
    let (mut samples, mut sdfs) = (Vec::new(), Vec::new());
    // Samples are evaluated MARCH_CHUNK at a time (one batch through the decoder); those past
    // the point where the light runs out are dropped, as if never drawn.
    'march: for taus in taus_m.chunks(MARCH_CHUNK) {
        if *transmittance < MIN_TRANSMITTANCE {
            break;
        }
        let points: Vec<DVec3> = taus.iter().map(|t| o + d * *t as f64).collect();
        for s in query(&points) {
            if *transmittance < MIN_TRANSMITTANCE {
                break 'march;
            }
            sdfs.push(s.sdf());
            samples.push(s);
            if let Some(a) = opacity.settled(&sdfs) {
                *transmittance *= 1.0 - a;
            }
        }
    }
    let (a, t) = opacity.alphas(&sdfs, taus_m);
    alphas.extend(a);
    at.extend(t);
    samples
}

/// What camera rays render with: the scene, its background (optional), β and the decoders.
#[derive(Clone, Copy)]
pub struct CameraModel<'a> {
    pub field: &'a SceneField,
    pub background: Option<&'a Background>,
    pub appearance: &'a Appearance,
    /// The scene's opacity model and β (the background's samples are per-sample at that β).
    pub opacity: Opacity,
    /// How many of the hash grids' coarsest levels the colour term's pose gradient sees
    /// (`None`: all; [`crate::unical::hash_grid::HashGrid::backward_and_grad_x`]). The scene
    /// still learns from every open level.
    pub pose_levels: Option<f32>,
}

impl CameraModel<'_> {
    fn background_opacity(&self) -> Opacity {
        Opacity {
            model: OpacityModel::PerSample,
            ..self.opacity
        }
    }
}

/// Everything one camera ray's forward pass computed, kept for its backward pass.
struct ColourForward {
    o: DVec3,
    d: DVec3,
    samples: Vec<FieldSample>,
    far_samples: Vec<FieldSample>,
    /// How many of the samples lie in the scene box (the rest are background samples).
    in_box: usize,
    alphas: Vec<f32>,
    /// The samples' distances along the ray, and where each one's weight sits.
    taus: Vec<f32>,
    at: Vec<f32>,
    features: Vec<f32>,
    c: super::composite::Composite,
    sky: super::mlp::Trace,
    t_sky: f32,
    dec: super::mlp::Trace,
    /// The decoder's colour before the exposure mapping, in [0, 1].
    rgb: Vec<f32>,
}

/// One ray's forward pass: march the box, then the background for the light that got through,
/// composite the features, add the sky for what is left and decode the colour (Eq. 3).
fn colour_forward(model: CameraModel, pose: &PoseParams, ray: &ColourRay) -> ColourForward {
    let CameraModel {
        field,
        background,
        appearance,
        ..
    } = model;
    let dim = field.geo.output_dim().saturating_sub(1);
    let (o, d) = pose.ray(ray.world_from_vehicle, ray.dir_in_sensor);
    let (mut alphas, mut at, mut transmittance) = (Vec::new(), Vec::new(), 1.0f32);
    let mut march_along =
        |query: &dyn Fn(&[DVec3]) -> Vec<FieldSample>, taus: &[f32], opacity: Opacity| {
            let out = (&mut alphas, &mut at);
            march(query, (o, d), taus, opacity, out, &mut transmittance)
        };
    let samples = march_along(&|x| field.query_many(x), &ray.taus_m, model.opacity);
    let in_box = samples.len();
    let far_samples = match background {
        Some(bg) => march_along(
            &|x| bg.query_many(x),
            &ray.background_taus_m,
            model.background_opacity(),
        ),
        None => Vec::new(),
    };
    let mut taus = ray.taus_m[..in_box].to_vec();
    taus.extend_from_slice(&ray.background_taus_m[..far_samples.len()]);
    let features: Vec<f32> = samples
        .iter()
        .chain(&far_samples)
        .flat_map(|s| s.feature().iter().copied())
        .collect();
    let c = composite(&alphas, &at, &features, dim);
    let sh: Vec<f32> = sh_encoding(d).iter().map(|v| *v as f32).collect();
    let sky = appearance.sky.forward(&sh);
    let t_sky = 1.0 - c.accumulation;
    let mut input: Vec<f32> = c
        .feature
        .iter()
        .zip(sky.output())
        .map(|(f, s)| f + t_sky * s)
        .collect();
    if appearance.view_dependent {
        input.extend_from_slice(&sh);
    } else {
        // Only the encoding's constant term.
        input.extend((0..SH_DIM).map(|k| if k == 0 { sh[0] } else { 0.0 }));
    }
    let dec = appearance.colour.forward(&input);
    let rgb: Vec<f32> = dec.output().iter().map(|v| sigmoid(*v)).collect();
    ColourForward {
        o,
        d,
        samples,
        far_samples,
        in_box,
        alphas,
        taus,
        at,
        features,
        c,
        sky,
        t_sky,
        dec,
        rgb,
    }
}

/// The colour camera `pose` sees along `ray` (after its exposure mapping), in [0, 1]: the
/// forward pass alone, for rendering whole images (e.g. held-out frames, method.md §13).
pub fn render_colour(
    model: CameraModel,
    pose: &PoseParams,
    exposure: &ExposureMap,
    ray: &ColourRay,
) -> [f32; 3] {
    let f = colour_forward(model, pose, ray);
    let mut out = [0.0f32; 3];
    for (ch, v) in out.iter_mut().enumerate() {
        let c = f.rgb.get(ch).copied().unwrap_or(0.0);
        *v = (exposure.scale[ch] * c + exposure.offset[ch]).clamp(0.0, 1.0);
    }
    out
}

/// Mean squared colour error of `rays` seen from `pose` and its gradients; the hash tables'
/// gradients go to `grid` (scene) and `background_grid`.
pub fn colour_step(
    model: CameraModel,
    pose: &PoseParams,
    exposure: &ExposureMap,
    rays: &[ColourRay],
    grid: &mut impl GradSink,
    background_grid: &mut impl GradSink,
) -> ColourStep {
    let CameraModel {
        field,
        background,
        appearance,
        ..
    } = model;
    let mut out = ColourStep {
        loss: 0.0,
        geo: field.geo.zero_grad(),
        colour: appearance.colour.zero_grad(),
        sky: appearance.sky.zero_grad(),
        background_mlp: background.map_or_else(MlpGrad::default, |b| b.geo.zero_grad()),
        beta_grad: 0.0,
        pose: PoseGrad::default(),
        exposure: [0.0; 6],
    };
    let n = rays.len().max(1) as f32;
    let dim = field.geo.output_dim().saturating_sub(1);
    for ray in rays {
        let ColourForward {
            o,
            d,
            samples,
            far_samples,
            in_box,
            alphas,
            taus,
            at,
            features,
            c,
            sky,
            t_sky,
            dec,
            rgb,
        } = colour_forward(model, pose, ray);
        // Loss and ∂L/∂(decoder logits).
        let mut d_logit = [0.0f32; 3];
        for ch in 0..3 {
            let pred = exposure.scale[ch] * rgb[ch] + exposure.offset[ch];
            let r = pred - ray.target[ch];
            out.loss += (r * r / n) as f64;
            let d_pred = 2.0 * r / n;
            out.exposure[ch] += (d_pred * rgb[ch]) as f64;
            out.exposure[3 + ch] += d_pred as f64;
            d_logit[ch] = d_pred * exposure.scale[ch] * rgb[ch] * (1.0 - rgb[ch]);
        }
        let d_input = appearance.colour.backward(&dec, &d_logit, &mut out.colour);
        let d_feature = &d_input[..dim];
        // Sky: F_total = F + T·f_sky, T = 1 − A.
        let d_sky: Vec<f32> = d_feature.iter().map(|g| g * t_sky).collect();
        let d_sh_sky = appearance.sky.backward(&sky, &d_sky, &mut out.sky);
        let d_t_sky: f32 = d_feature.iter().zip(sky.output()).map(|(g, s)| g * s).sum();
        let view = if appearance.view_dependent { 1.0 } else { 0.0 };
        let d_sh: Vec<f32> = d_input[dim..]
            .iter()
            .zip(&d_sh_sky)
            .map(|(a, b)| view * a + b)
            .collect();
        let up = Upstream {
            accumulation: -d_t_sky,
            feature: d_feature,
            ..Upstream::default()
        };
        let (d_alpha, d_features) = composite_backward(&alphas, &at, &features, dim, &c, &up);
        let split = (in_box, in_box * dim);
        let (mut d_o, mut d_d, d_beta) = field.ray_backward(
            &samples,
            &taus[..in_box],
            model.opacity,
            (&d_alpha[..split.0], &d_features[..split.1]),
            grid,
            &mut out.geo,
            model.pose_levels,
        );
        out.beta_grad += d_beta;
        if let Some(bg) = background.filter(|_| !far_samples.is_empty()) {
            let (far_o, far_d, far_beta) = bg.ray_backward(
                (o, d),
                &far_samples,
                &taus[in_box..],
                model.background_opacity(),
                (&d_alpha[split.0..], &d_features[split.1..]),
                background_grid,
                &mut out.background_mlp,
                model.pose_levels,
            );
            d_o += far_o;
            d_d += far_d;
            out.beta_grad += far_beta;
        }
        d_d += sh_backward(d, &d_sh);
        out.pose
            .add(&pose.ray_backward(ray.world_from_vehicle, ray.dir_in_sensor, d_o, d_d));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::field::tiny_field;
    use super::super::hash_grid::HashGridConfig;
    use super::super::pose::assert_pose_gradient;
    use super::*;
    use crate::unical::hash_grid::SparseGrad;
    use glam::DQuat;

    /// The colour term's model over the test scene at β = 3, every level in the pose gradient.
    fn model_of<'a>(
        field: &'a SceneField,
        background: &'a Background,
        appearance: &'a Appearance,
        opacity: OpacityModel,
    ) -> CameraModel<'a> {
        CameraModel {
            field,
            background: Some(background),
            appearance,
            opacity: Opacity {
                model: opacity,
                beta: 3.0,
            },
            pose_levels: None,
        }
    }

    fn setup() -> (
        SceneField,
        Background,
        Appearance,
        PoseParams,
        Vec<ColourRay>,
    ) {
        let field = tiny_field(3, 4.0, 20.0);
        // A smooth background (coarse levels): its unit coordinates are f32, so at hundreds of
        // metres finite differences in the pose only resolve slowly varying fields.
        let smooth = super::super::background::BackgroundConfig {
            grid: HashGridConfig {
                levels: 2,
                log2_table_size: 10,
                base_resolution: 4.0,
                max_resolution: 16.0,
            },
            ..Default::default()
        };
        let mut background =
            Background::new(DVec3::splat(-20.0), DVec3::splat(20.0), 3, &smooth, 6);
        for (i, p) in background.grid.params.iter_mut().enumerate() {
            *p = ((i as f32 * 0.5698).fract() - 0.5) * 2.0;
        }
        let appearance = Appearance::new(3, 9);
        let pose = PoseParams::from_rigid(Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, -1.4, 0.03, -1.6),
            DVec3::new(1.5, -0.2, 1.6),
        ));
        let rays = (0..8)
            .map(|i| {
                let world_from_vehicle = Rigid::new(
                    DQuat::from_rotation_z(0.05 * i as f64),
                    DVec3::new(1.0 + i as f64 * 0.2, 0.5, 0.0),
                );
                let dir_in_sensor = DVec3::new(0.1 * i as f64 - 0.4, 0.2, 1.0).normalize_or_zero();
                let (o, d) = pose.ray(world_from_vehicle, dir_in_sensor);
                // Odd rays cross little of the box, so the background shows through.
                let in_box = if i % 2 == 0 { 50 } else { 2 };
                ColourRay {
                    world_from_vehicle,
                    dir_in_sensor,
                    target: [0.2 + 0.05 * i as f32, 0.5, 0.7 - 0.04 * i as f32],
                    taus_m: (1..in_box).map(|k| k as f32 * 0.2).collect(),
                    background_taus_m: background.taus(o, d, 0.3),
                }
            })
            .collect();
        (field, background, appearance, pose, rays)
    }

    #[test]
    fn spherical_harmonics_are_orthonormal_on_the_sphere() {
        // Monte-Carlo on a Fibonacci sphere: ∫ Y_i Y_j dω ≈ δ_ij.
        let n = 20_000;
        let mut gram = [[0.0f64; SH_DIM]; SH_DIM];
        for k in 0..n {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
            let phi = k as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let r = (1.0 - z * z).sqrt();
            let y = sh_encoding(DVec3::new(r * phi.cos(), r * phi.sin(), z));
            for i in 0..SH_DIM {
                for j in 0..SH_DIM {
                    gram[i][j] += y[i] * y[j] * 4.0 * std::f64::consts::PI / n as f64;
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-2, "({i},{j}): {v}");
            }
        }
    }

    /// The whole chain — field, compositing with early stop, sky, decoder, SH of the view
    /// direction, 6D pose — against finite differences of the loss in the pose, and the
    /// exposure gradients likewise.
    #[test]
    fn rendered_colours_are_what_the_loss_compares() {
        // The training loss is the mean squared difference between render_colour and the
        // targets (no clamping at this exposure: the decoder's sigmoid stays inside (0, 1)).
        let (field, background, appearance, pose, rays) = setup();
        let model = model_of(&field, &background, &appearance, OpacityModel::Interval);
        let exposure = ExposureMap {
            scale: [0.9, 0.8, 0.85],
            offset: [0.02, 0.01, 0.0],
        };
        let step = colour_step(
            model,
            &pose,
            &exposure,
            &rays,
            &mut SparseGrad::default(),
            &mut SparseGrad::default(),
        );
        let mse: f64 = rays
            .iter()
            .map(|r| {
                let c = render_colour(model, &pose, &exposure, r);
                (0..3)
                    .map(|k| ((c[k] - r.target[k]) as f64).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / rays.len() as f64;
        assert!(
            (mse - step.loss).abs() < 1e-6 * step.loss.max(1e-3),
            "{mse} vs {}",
            step.loss
        );
    }

    /// Limiting the pose gradient to the coarse levels changes the pose's gradient alone: the
    /// scene's and background's table gradients and the loss stay as they were, and with every
    /// level counted the pose gradient is the unlimited one.
    #[test]
    fn pose_levels_change_only_the_pose_gradient() {
        let (field, background, appearance, pose, rays) = setup();
        let model = model_of(&field, &background, &appearance, OpacityModel::PerSample);
        let run = |pose_levels| {
            let (mut grid, mut far) = (SparseGrad::default(), SparseGrad::default());
            let m = CameraModel {
                pose_levels,
                ..model
            };
            let step = colour_step(
                m,
                &pose,
                &ExposureMap::default(),
                &rays,
                &mut grid,
                &mut far,
            );
            (step, grid.entries, far.entries)
        };
        let (all, grid, far) = run(None);
        let (every, _, _) = run(Some(100.0));
        assert_eq!(every.pose.r6, all.pose.r6);
        assert_eq!(every.pose.translation_m, all.pose.translation_m);
        let (coarse, coarse_grid, coarse_far) = run(Some(1.0));
        assert_eq!(coarse.loss, all.loss);
        assert_eq!((coarse_grid, coarse_far), (grid, far));
        let moved = (coarse.pose.translation_m - all.pose.translation_m).length();
        assert!(moved > 1e-6 * all.pose.translation_m.length(), "{moved}");
    }

    #[test]
    fn pose_and_exposure_gradients_match_finite_differences() {
        for opacity in [OpacityModel::PerSample, OpacityModel::Interval] {
            pose_and_exposure_gradients_of(opacity, true);
        }
        // View-independent surface colour (the sky still follows the direction).
        pose_and_exposure_gradients_of(OpacityModel::PerSample, false);
    }

    fn pose_and_exposure_gradients_of(opacity: OpacityModel, view_dependent: bool) {
        let (field, background, appearance, pose, rays) = setup();
        let appearance = Appearance {
            view_dependent,
            ..appearance
        };
        let model = model_of(&field, &background, &appearance, opacity);
        let exposure = ExposureMap {
            scale: [0.9, 1.1, 1.0],
            offset: [0.02, -0.01, 0.0],
        };
        let mut background_grid = SparseGrad::default();
        let step = colour_step(
            model,
            &pose,
            &exposure,
            &rays,
            &mut SparseGrad::default(),
            &mut background_grid,
        );
        assert!(
            background_grid.entries.iter().any(|e| e.1 != [0.0; 2]),
            "the background was not reached"
        );
        assert!(step.loss > 0.0);
        let loss = |p: &PoseParams, e: &ExposureMap| {
            colour_step(
                model,
                p,
                e,
                &rays,
                &mut SparseGrad::default(),
                &mut SparseGrad::default(),
            )
            .loss
        };
        let norm = step.pose.r6.iter().map(|g| g * g).sum::<f64>().sqrt()
            + step.pose.translation_m.length();
        assert!(norm > 1e-3, "gradient too small to test: {norm}");
        let tol = 0.02 * norm;
        // Small steps: hash-grid cells, ReLUs and the early stop make the loss only piecewise
        // smooth, so wide central differences straddle kinks.
        let eps = 3e-4;
        assert_pose_gradient(pose, &step.pose, eps, tol, |p| loss(p, &exposure));
        for k in 0..6 {
            let (mut up, mut down) = (exposure, exposure);
            if k < 3 {
                up.scale[k] += 1e-3;
                down.scale[k] -= 1e-3;
            } else {
                up.offset[k - 3] += 1e-3;
                down.offset[k - 3] -= 1e-3;
            }
            let fd = (loss(&pose, &up) - loss(&pose, &down)) / 2e-3;
            let an = step.exposure[k];
            assert!(
                (fd - an).abs() < 1e-3 + 0.01 * an.abs(),
                "exposure[{k}]: {fd} vs {an}"
            );
        }
        // The background field's parameters: its MLP's largest gradients per layer.
        for layer in 0..background.geo.layers.len() {
            let g = &step.background_mlp.weights[layer];
            let mut order: Vec<usize> = (0..g.len()).collect();
            order.sort_by(|a, b| g[*b].abs().total_cmp(&g[*a].abs()));
            assert!(
                g[order[0]].abs() > 1e-4,
                "no background gradient: {}",
                g[order[0]]
            );
            for &k in order.iter().take(3) {
                let at = |delta: f32| {
                    let mut bg = background.clone();
                    bg.geo.layers[layer].weights_mut()[k] += delta;
                    let m = CameraModel {
                        background: Some(&bg),
                        ..model
                    };
                    colour_step(
                        m,
                        &pose,
                        &exposure,
                        &rays,
                        &mut SparseGrad::default(),
                        &mut SparseGrad::default(),
                    )
                    .loss
                };
                let fd = (at(1e-3) - at(-1e-3)) / 2e-3;
                let an = g[k] as f64;
                assert!(
                    (fd - an).abs() < 2e-4 + 0.02 * an.abs(),
                    "background layer {layer} weight {k}: {fd} vs {an}"
                );
            }
        }
    }
}
