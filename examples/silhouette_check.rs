#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The simulator's silhouette acceptance measure in detail ([`SilhouetteCheck`]): the
//! distribution of the LiDAR silhouette points' distances to the nearest image edge with the
//! true extrinsics and with the camera 1° off (the means are what `tests/sim_acceptance.rs`
//! bounds). Writes the edge map with the silhouette points drawn over it (green within 1 px of
//! an edge, red beyond) and the rendered image beside it.
//! `cargo run --release --example silhouette_check -- [OUT.png] [SCENE_SEED]`

use rigcal::sim::silhouettes::SilhouetteCheck;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .cloned()
        .unwrap_or_else(|| "silhouettes.png".into());
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let check = SilhouetteCheck::stationary(seed).unwrap();
    for error_deg in [0.0, 1.0] {
        let px = check.pixels(error_deg).unwrap();
        let inside = check.distances(&px);
        let mut d: Vec<f32> = inside.iter().map(|(_, d)| *d).collect();
        d.sort_by(f32::total_cmp);
        let n = d.len();
        let share = |lo: f32, hi: f32| d.iter().filter(|&&x| x >= lo && x < hi).count();
        let q = |f: f64| d[((n as f64 * f) as usize).min(n - 1)];
        let tail = d.iter().filter(|&&x| x > 3.0).sum::<f32>() / n as f32;
        println!(
            "{error_deg}°: {n} points, mean {:.3} px; median {:.2}, p90 {:.2}, p99 {:.2}, max {:.1}; \
             on an edge {}, 1 px off {}, 1.5–3 px {}, beyond 3 px {} (contributing {tail:.3} px of the mean)",
            check.mean_distance(&px).unwrap(),
            q(0.5),
            q(0.9),
            q(0.99),
            d[n - 1],
            share(0.0, 1.0),
            share(1.0, 1.5),
            share(1.5, 3.0),
            share(3.0, f32::INFINITY),
        );
        if error_deg == 0.0 {
            let (w, h) = (check.image.width(), check.image.height());
            let mut overlay = image::RgbImage::from_fn(w, h, |x, y| {
                if check.edges[(y * w + x) as usize] {
                    image::Rgb([255, 255, 255])
                } else {
                    let g = check.image.get_pixel(x, y)[0] / 3;
                    image::Rgb([g, g, g])
                }
            });
            for &(p, dist) in &inside {
                let (x, y) = (p[0].round() as u32, p[1].round() as u32);
                let c = if dist <= 1.0 {
                    [0, 255, 0]
                } else {
                    [255, 0, 0]
                };
                overlay.put_pixel(x, y, image::Rgb(c));
            }
            overlay.save(&out).unwrap();
            check.image.save(out.replace(".png", "-image.png")).unwrap();
        }
    }
}
