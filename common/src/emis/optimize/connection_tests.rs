//! Tests of per-pixel connection counts in the optimiser ([`ConnectionScope::PerPixel`]).

use super::*;
use crate::emis::candidate::CandidateConfig;
use crate::emis::cost::pixel_cost;

fn input<'a>(
    candidates: &'a [Candidate],
    moments: &'a MomentBuffer,
    image: &'a Image,
    connection_scope: ConnectionScope,
) -> OptimizerInput<'a> {
    OptimizerInput {
        restart_share: 0.0,
        incumbent: None,
        candidates,
        moments,
        image,
        statistics: PathStatistics::default(),
        constants: CostConstants::default(),
        filters: FilterSettings::default(),
        merge_scope: MergeScope::PerPixel,
        connection_scope,
    }
}

/// BDPT candidates on 96²: at ν = 1, four connections are 10× better than anything inside a
/// disk and none are best outside it. Per pixel, the connection mask is 4 in the disk, falls
/// off over the dilation and blur (radii 3 and 16 at 640×480: 1 and 3 at 96²), and is 0 far
/// from it; ν is the only image-level choice. With the image scope there is no mask.
#[test]
fn per_pixel_connections_follow_where_they_win() {
    let candidates = CandidateConfig::bdpt().candidates();
    let (w, h) = (96u32, 96u32);
    let in_disk = |p: u32| {
        let (x, y) = ((p % w) as f32 - 48.0, (p / w) as f32 - 48.0);
        x * x + y * y < 10.0 * 10.0
    };
    let cost = |c: &Candidate| pixel_cost(&CostConstants::default(), &PathStatistics::default(), c, 0.0, false, w * h);
    // moment × cost: 0.1 for the winner of each region, 1 for every other candidate
    let moments = buffer(w, h, &candidates, |p, c| {
        let wins = c.nu == 1.0 && c.connections == if in_disk(p) { 4 } else { 0 };
        if wins { 0.1 / cost(c) } else { 1.0 / cost(c) }
    });
    let image = Image::filled(w as usize, h as usize, 0.5);
    let d = optimize(&input(&candidates, &moments, &image, ConnectionScope::PerPixel));
    assert_eq!((d.nu, d.connections), (1.0, 0));
    let mask = d.connection_mask.as_ref().expect("a connection mask");
    let c = |x: u32, y: u32| mask.data[(y * w + x) as usize];
    assert_eq!(FilterSettings::default().connection_radii(96, 96), (1, 3));
    assert_eq!(c(48, 48), 4.0, "4 in the disk");
    assert_eq!((c(0, 0), c(95, 95)), (0.0, 0.0), "0 far from it");
    // the disk's last pixel is x = 57; dilated to 58, blurred by 3 box passes (±3 px)
    assert!(c(58, 48) > 2.0 && c(58 + 3, 48) > 0.0 && c(58 + 4, 48) == 0.0, "{:?}", (58..63).map(|x| c(x, 48)));
    let profile: Vec<f32> = (48..96).map(|x| c(x, 48)).collect();
    assert!(profile.windows(2).all(|p| p[1] <= p[0] + 1e-6), "monotone");
    assert!(d.scores.iter().all(|s| s.connections.is_none() == (s.nu > 0.0)), "ν alone at the image level");
    assert_eq!(d.scores.len(), 6, "five ν and path tracing");
    // the same moments with one c for the image
    let image_level = optimize(&input(&candidates, &moments, &image, ConnectionScope::Image));
    assert!(image_level.connection_mask.is_none());
    assert_eq!(image_level.nu, 1.0);
    assert!([0, 4].contains(&image_level.connections), "{}", image_level.connections);
    assert_eq!(image_level.scores.len(), 26);
}

/// Path tracing winning the image level leaves no connection mask, whatever the pixel level
/// found.
#[test]
fn path_tracing_needs_no_connection_mask() {
    let candidates = CandidateConfig::vcm().candidates();
    let moments = buffer(16, 16, &candidates, |_, c| if c.is_path_tracing() { 1e-3 } else { 1.0 });
    let image = Image::filled(16, 16, 0.5);
    let d = optimize(&input(&candidates, &moments, &image, ConnectionScope::PerPixel));
    assert_eq!((d.nu, d.connections, d.connection_mask.is_none()), (0.0, 0, true));
}

#[test]
fn connection_classes_round_up_to_a_candidate_count() {
    let classes = connection_classes(&CandidateConfig::vcm().candidates());
    assert_eq!(classes, [0, 1, 2, 4, 8]);
    let class = |c: f32| classes[class_of(&classes, c) as usize];
    assert_eq!([class(0.0), class(0.2), class(1.0), class(1.3), class(4.0), class(7.9)], [0, 1, 1, 2, 4, 8]);
    assert_eq!(class(4.00001), 4, "float noise of a blurred constant stays in its class");
    assert_eq!(class(9.0), 8, "beyond the largest: the largest");
}

/// With per-pixel connections the image-level sums equal their per-pixel definition bit for
/// bit: each pixel reads the candidate (ν, its class, its merge bit).
#[test]
fn per_pixel_classes_sum_as_their_definition_bit_for_bit() {
    let (candidates, moments, image) = random_input(51, 11);
    let (w, h) = (image.width, image.height);
    let norm: Vec<f32> = image.data.iter().map(|&i| i * i + 1e-4).collect();
    let stats = PathStatistics { camera_vertices: 4.0, light_vertices: 3.0, photons_per_query_per_path: 2e-6 };
    let constants = CostConstants::default();
    let costs = CostTerms::of_candidates(&constants, &stats, &candidates, (w * h) as u32);
    let (filtered, _) = planes::moment_planes(&moments, false);
    let thresholds = planes::thresholds(&filtered, &norm, 0.999);
    let mut s = crate::sampler::Sampler::for_pixel(9, 0, 0);
    let mask = Image::from_data(w, h, (0..w * h).map(|p| if p % 40 < 15 { 0.0 } else { 0.2 * s.next_1d() }).collect());
    let class_counts = connection_classes(&candidates);
    let classes: Vec<u8> = (0..w * h).map(|p| ((p / 7 + p % 5) % class_counts.len()) as u8).collect();
    let input = OptimizerInput {
        restart_share: 0.0,
        incumbent: None,
        statistics: stats,
        ..input(&candidates, &moments, &image, ConnectionScope::PerPixel)
    };
    let groups = image_level_groups(&candidates, MergeScope::PerPixel, Some(&class_counts));
    let got = image_level_scores(&input, &groups, &filtered, &norm, &costs, Some(&mask), Some(&classes), &thresholds);
    for (g, score) in groups.iter().zip(&got) {
        let map_built = mask.data.iter().any(|&chi| chi > 0.1);
        let (mut rel, mut cost) = (0.0f64, 0.0f64);
        for (p, (&i, &n)) in image.data.iter().zip(&norm).enumerate() {
            let i = i as f64;
            if i == 0.0 {
                continue;
            }
            let k = if g.nu == 0.0 { 0 } else { class_counts[classes[p] as usize] };
            let merge = mask.data[p] > 0.1;
            let c = candidates
                .iter()
                .position(|c| c.nu == g.nu && (c.is_path_tracing() || (c.connections == k && c.merge == merge)))
                .expect("every variant exists");
            let on = candidates.iter().position(|c| c.nu == g.nu && c.merge);
            let shared_build = match on {
                Some(on) if map_built && !candidates[c].merge => costs[on].build(),
                _ => 0.0,
            };
            cost += (costs[c].at(candidates[c].merge as u8 as f64) + shared_build) / (w * h) as f64;
            let mut moment = filtered[c][p];
            if moment / n > thresholds[c] && moment.is_finite() {
                moment = 0.0;
            }
            rel += moment as f64 * (1.0 / ((i * i + 1e-4) * (w * h) as f64));
        }
        assert_eq!(
            (score.relative_moment.to_bits(), score.cost.to_bits()),
            (rel.to_bits(), cost.to_bits()),
            "ν {}",
            g.nu
        );
    }
}
