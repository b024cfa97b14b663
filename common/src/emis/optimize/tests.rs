//! Tests of the optimiser on synthetic moments (docs/emis.md, checklist 11 and 12).

use super::*;
use crate::emis::candidate::CandidateConfig;
use crate::emis::cost::pixel_cost;
use crate::emis::delta::Delta;

/// A moment buffer with `value(pixel, candidate)` as every candidate's per-iteration moment.
fn buffer(w: u32, h: u32, candidates: &[Candidate], value: impl Fn(u32, &Candidate) -> f64) -> MomentBuffer {
    let mut b = MomentBuffer::new(w, h, candidates.len());
    for p in 0..w * h {
        for (c, cand) in candidates.iter().enumerate() {
            let v = value(p, cand);
            b.add(
                p,
                c,
                if v.is_finite() { Delta::Finite(1.0) } else { Delta::Infinite },
                if v.is_finite() { v } else { 0.0 },
            );
        }
    }
    b.iterations = 1;
    b
}

fn run(candidates: &[Candidate], moments: &MomentBuffer, image: &Image) -> Decision {
    run_with(candidates, moments, image, FilterSettings::default())
}

fn run_with(candidates: &[Candidate], moments: &MomentBuffer, image: &Image, filters: FilterSettings) -> Decision {
    optimize(&OptimizerInput {
        restart_share: 0.0,
        incumbent: None,
        candidates,
        moments,
        image,
        statistics: PathStatistics::default(),
        constants: CostConstants::default(),
        filters,
        merge_scope: MergeScope::PerPixel,
        connection_scope: ConnectionScope::Image,
    })
}

/// Every candidate's relative moment is 2 everywhere, including on a tiny feature 1000×
/// brighter than the rest. Made relative before the filter, the image-level relative moment
/// stays 2 (filtered as absolute moments, the retired order, the feature's M spread into its
/// dim surroundings and the mean exploded past 100: the veach-mis failure of decision 0003).
/// The reference's outlier rule alone: the shared rule would take the feature's pixels out
/// first (they are the top 0.1 % of the shared relative moment, by rounding), and nothing
/// would spread.
#[test]
fn a_bright_feature_does_not_spread_relative_moment_into_its_surroundings() {
    let candidates = CandidateConfig::bdpt().candidates();
    let (w, h) = (64u32, 64u32);
    let intensity = |p: u32| if (30..32).contains(&(p % w)) && (30..32).contains(&(p / w)) { 1000.0 } else { 1.0 };
    let moments = buffer(w, h, &candidates, |p, _| 2.0 * intensity(p) * intensity(p));
    let image = Image::from_data(w as usize, h as usize, (0..w * h).map(|p| intensity(p) as f32).collect());
    let reference_rule = FilterSettings { outliers: OutlierStage::Filtered, ..FilterSettings::default() };
    let relative = run_with(&candidates, &moments, &image, reference_rule);
    for s in &relative.scores {
        // the outlier rejection may zero up to 0.1 % of the (equal) pixels
        assert!((s.relative_moment - 2.0).abs() <= 2.0 * 0.0015, "{s:?}");
    }
}

#[test]
fn merging_that_wins_in_a_disk_gives_a_dilated_blurred_disk() {
    let candidates = CandidateConfig::vcm().candidates();
    let (w, h) = (96u32, 96u32);
    let in_disk = |p: u32| {
        let (x, y) = ((p % w) as f32 - 48.0, (p / w) as f32 - 48.0);
        x * x + y * y < 10.0 * 10.0
    };
    // merging is 1000x better inside the disk, useless (no better, more costly) outside
    let b = buffer(w, h, &candidates, |p, c| if c.merge && in_disk(p) { 0.001 } else { 1.0 });
    let d = run(&candidates, &b, &Image::filled(w as usize, h as usize, 1.0));
    let chi = |x: u32, y: u32| d.merge_mask.data[(y * w + x) as usize];
    // 96² is 0.17 of 640×480's linear size: radii 16 scale to 3
    assert_eq!(FilterSettings::default().mask_radii(96, 96), (3, 3));
    assert_eq!(chi(48, 48), 1.0, "χ = 1 in the disk");
    // the disk's last pixel is x = 57; dilated to 60, blurred by 3 box passes (±3 px)
    assert!(chi(48 + 9 + 3, 48) > 0.5, "dilated by 3 px");
    assert!(chi(48 + 9 + 3 + 3, 48) > 0.0, "blurred by 3 px");
    assert!(chi(48 + 9 + 3 + 4, 48) == 0.0, "falls to 0 beyond dilation + blur");
    // smooth fall-off: monotone from the disk outwards over the blur
    let profile: Vec<f32> = (48..96).map(|x| chi(x, 48)).collect();
    assert!(profile.windows(2).all(|p| p[1] <= p[0] + 1e-6), "monotone");
    let transition = profile.iter().filter(|&&v| v > 0.0 && v < 1.0).count();
    assert!(transition >= 5, "a gradual edge, not a step: {transition} px");
}

#[test]
fn mask_radii_follow_the_image_size() {
    let f = FilterSettings::default();
    assert_eq!(f.mask_radii(640, 480), (16, 16));
    assert_eq!(f.mask_radii(256, 256), (7, 7));
    assert_eq!(f.mask_radii(1920, 1080), (42, 42));
    assert_eq!(f.mask_radii(8, 8), (1, 1), "never below one pixel");
    assert_eq!(FilterSettings { mask_dilate: 0, ..f }.mask_radii(1920, 1080), (0, 42));
}

#[test]
fn a_two_times_lower_moment_at_equal_cost_wins_and_scaling_changes_nothing() {
    let candidates = CandidateConfig::bdpt().candidates();
    let target = Candidate { nu: 0.5, connections: 2, merge: false };
    let cost_target = pixel_cost(&CostConstants::default(), &PathStatistics::default(), &target, 0.0, false, 32 * 32);
    // every candidate's moment × cost equals 1, except the target's, which is 0.5
    let m = |_: u32, c: &Candidate| {
        let cc = pixel_cost(&CostConstants::default(), &PathStatistics::default(), c, 0.0, c.merge, 32 * 32);
        if *c == target { 0.5 / cost_target } else { 1.0 / cc }
    };
    let img = Image::filled(32, 32, 0.7);
    let d = run(&candidates, &buffer(32, 32, &candidates, m), &img);
    assert_eq!((d.nu, d.connections), (0.5, 2));
    let scaled = run(&candidates, &buffer(32, 32, &candidates, |p, c| 1e6 * m(p, c)), &img);
    assert_eq!((scaled.nu, scaled.connections), (d.nu, d.connections), "scaling all moments changes no decision");
    assert!(d.merge_mask.data.iter().all(|&v| v == 0.0), "bdpt never merges");
}

/// A challenger 10 % better than every other candidate replaces the incumbent (ν 1, c 1) under
/// any margin when it costs more, and only under a margin below 10 % when it costs less; a
/// margin of 0 or no incumbent keeps the plain argmin.
#[test]
fn a_cheaper_challenger_must_beat_the_incumbent_by_its_margin() {
    let candidates = CandidateConfig::bdpt().candidates();
    let cost =
        |c: &Candidate| pixel_cost(&CostConstants::default(), &PathStatistics::default(), c, 0.0, c.merge, 32 * 32);
    let incumbent = Candidate { nu: 1.0, connections: 1, merge: false };
    let cheaper = Candidate { nu: 0.5, connections: 1, merge: false };
    let dearer = Candidate { nu: 2.0, connections: 2, merge: false };
    assert!(cost(&cheaper) < cost(&incumbent) && cost(&incumbent) < cost(&dearer));
    let image = Image::filled(32, 32, 0.7);
    let decide = |challenger: Candidate, margin: Option<f64>| {
        let m = |_: u32, c: &Candidate| if *c == challenger { 0.9 / cost(c) } else { 1.0 / cost(c) };
        let moments = buffer(32, 32, &candidates, m);
        let incumbent = margin.map(|margin| Incumbent { nu: 1.0, connections: Some(1), margin });
        let d = optimize(&OptimizerInput {
            restart_share: 0.0,
            incumbent,
            candidates: &candidates,
            moments: &moments,
            image: &image,
            statistics: PathStatistics::default(),
            constants: CostConstants::default(),
            filters: FilterSettings::default(),
            merge_scope: MergeScope::PerPixel,
            connection_scope: ConnectionScope::Image,
        });
        (d.nu, d.connections)
    };
    for margin in [None, Some(0.0), Some(0.05)] {
        assert_eq!(decide(cheaper, margin), (0.5, 1), "margin {margin:?}");
    }
    assert_eq!(decide(cheaper, Some(0.2)), (1.0, 1));
    assert_eq!(decide(dearer, Some(0.2)), (2.0, 2));
    assert!((Incumbent::margin_after(0.25, 4) - 0.125).abs() < 1e-12);
}

/// The path-tracing start's decisions: every reduced candidate is an image-level one, and
/// the winner merges everywhere or nowhere, whatever the per-pixel picture.
#[test]
fn global_merge_scope_scores_every_candidate_and_gives_a_constant_mask() {
    let candidates = CandidateConfig::vcm().reduced().candidates();
    let (w, h) = (48u32, 48u32);
    let stats = PathStatistics::default();
    let cost = |c: &Candidate| {
        let chi = if c.merge { 1.0 } else { 0.0 };
        pixel_cost(&CostConstants::default(), &stats, c, chi, c.merge, w * h)
    };
    let img = Image::filled(w as usize, h as usize, 0.5);
    for target in [
        Candidate { nu: 0.5, connections: 1, merge: true },
        Candidate { nu: 1.0, connections: 0, merge: false },
        Candidate::PATH_TRACING,
    ] {
        // the target's moment × cost is half everyone else's, varying over the image; in
        // a small corner merging is 10× worse (a per-pixel decision would not merge there)
        let b = buffer(w, h, &candidates, |p, c| {
            let corner = p % w < 4 && p / w < 4;
            let v = if *c == target { 0.5 } else { 1.0 } * (1.0 + (p % 7) as f64 * 0.1);
            if corner && c.merge { 10.0 * v / cost(c) } else { v / cost(c) }
        });
        let d = optimize(&OptimizerInput {
            restart_share: 0.0,
            incumbent: None,
            candidates: &candidates,
            moments: &b,
            image: &img,
            statistics: stats,
            constants: CostConstants::default(),
            filters: FilterSettings::default(),
            merge_scope: MergeScope::Global,
            connection_scope: ConnectionScope::Image,
        });
        assert_eq!((d.nu, d.connections), (target.nu, target.connections), "{target:?}");
        assert_eq!(d.scores.len(), 9);
        assert!(d.scores.iter().all(|s| s.merge.is_some()));
        let chi = if target.merge { 1.0 } else { 0.0 };
        assert!(d.merge_mask.data.iter().all(|&v| v == chi), "χ = {chi} everywhere for {target:?}");
    }
}

/// A few huge samples that every candidate shares (paths only the camera's own techniques
/// can sample, δ = 1 for all: caustic-glass's caustics seen through the glass) cannot be
/// improved by any strategy, yet they lift every candidate's mean alike, so that the
/// cheapest one wins. Rejected where they landed, they change nothing; box-filtered first,
/// each spreads over 49 pixels, escapes the 0.1 % rejection and decides.
#[test]
fn rare_samples_every_candidate_shares_do_not_decide() {
    let candidates = CandidateConfig::bdpt().candidates();
    let (w, h) = (64u32, 64u32);
    let target = Candidate { nu: 1.0, connections: 1, merge: false };
    let stats = PathStatistics::default();
    let cost = |c: &Candidate| pixel_cost(&CostConstants::default(), &stats, c, 0.0, c.merge, w * h);
    // moment × cost is 1 for every candidate, 0.8 for the target; three pixels got a
    // sample worth 2e4 relative moment in every candidate
    let spikes = [w * 10 + 10, w * 30 + 40, w * 50 + 20];
    let b = buffer(w, h, &candidates, |p, c| {
        let own = if *c == target { 0.8 } else { 1.0 } / cost(c);
        own + if spikes.contains(&p) { 2e4 } else { 0.0 }
    });
    let img = Image::filled(w as usize, h as usize, 1.0);
    let decide = |outliers| {
        let d = run_with(&candidates, &b, &img, FilterSettings { outliers, ..FilterSettings::default() });
        (d.nu, d.connections)
    };
    assert_eq!(decide(OutlierStage::Shared), (target.nu, target.connections));
    assert_eq!(decide(OutlierStage::Filtered), (0.0, 0), "filtered first, the spikes make the cheapest win");
}

#[test]
fn candidates_that_cannot_sample_never_win() {
    let candidates = CandidateConfig::bdpt().candidates();
    // path tracing looks cheapest and perfect, but cannot sample some paths: infinite
    let b =
        buffer(
            16,
            16,
            &candidates,
            |p, c| {
                if c.is_path_tracing() { if p == 5 { f64::INFINITY } else { 0.0 } } else { 1.0 }
            },
        );
    let d = run(&candidates, &b, &Image::filled(16, 16, 1.0));
    assert!(d.nu > 0.0, "a bidirectional candidate is chosen: {d:?}");
}

/// Issue 21, fault 2: emis-bdpt never builds a photon map, so the optimiser must not charge
/// its candidates for one (it matters with the reference cost model, whose map build has a
/// cost). Every candidate's moment × (map-free) cost is 1 but that of ν = 1, c = 1, which is
/// 0.85: it must win. Charged for a map, it would cost more than 1 / 0.85 times as much and lose.
#[test]
fn bdpt_candidates_pay_nothing_for_a_photon_map() {
    let candidates = CandidateConfig::bdpt().candidates();
    let target = Candidate { nu: 1.0, connections: 1, merge: false };
    let (k, stats) = (CostConstants::reference(), PathStatistics::default());
    let with_map = pixel_cost(&k, &stats, &target, 0.0, true, 32 * 32);
    let without = pixel_cost(&k, &stats, &target, 0.0, false, 32 * 32);
    assert!(with_map / without > 1.0 / 0.85, "the test needs a map that matters: {with_map} vs {without}");
    let m = |_: u32, c: &Candidate| {
        let cost = pixel_cost(&k, &stats, c, 0.0, false, 32 * 32);
        if *c == target { 0.85 / cost } else { 1.0 / cost }
    };
    let d = optimize(&OptimizerInput {
        restart_share: 0.0,
        incumbent: None,
        candidates: &candidates,
        moments: &buffer(32, 32, &candidates, m),
        image: &Image::filled(32, 32, 0.7),
        statistics: stats,
        constants: k,
        filters: FilterSettings::default(),
        merge_scope: MergeScope::PerPixel,
        connection_scope: ConnectionScope::Image,
    });
    assert_eq!((d.nu, d.connections), (1.0, 1));
    let terms = CostTerms::of_candidates(&k, &stats, &candidates, 32 * 32);
    for (c, t) in candidates.iter().zip(&terms) {
        assert_eq!(*t, CostTerms::new(&k, &stats, c, false, 32 * 32), "{c:?} pays for a map");
    }
}

/// Issue 21, fault 3: the image-level sums price merging as they judge it, binary (χ > 0.1
/// merges), over the pixels they judge (not the black ones), and a per-pixel group whose mask
/// merges anywhere pays for the photon map in every pixel. With every candidate's moment
/// equal, a mask of χ = 0.2 must not make a group look cheaper than a mask of χ = 1.
#[test]
fn image_level_cost_prices_merging_as_binary_over_the_judged_pixels() {
    let candidates = CandidateConfig::vcm().reduced().candidates();
    let (w, h) = (16usize, 16usize);
    let (k, stats) = (CostConstants::reference(), PathStatistics::default());
    let moments = buffer(w as u32, h as u32, &candidates, |_, _| 1.0);
    // the left half of the image is black
    let image = Image::from_data(w, h, (0..w * h).map(|p| if p % w < w / 2 { 0.0 } else { 0.5 }).collect());
    let input = OptimizerInput {
        restart_share: 0.0,
        incumbent: None,
        candidates: &candidates,
        moments: &moments,
        image: &image,
        statistics: stats,
        constants: k,
        filters: FilterSettings::default(),
        merge_scope: MergeScope::PerPixel,
        connection_scope: ConnectionScope::Image,
    };
    let norm: Vec<f32> = image.data.iter().map(|&i| i * i + 1e-4).collect();
    let (filtered, _) = planes::moment_planes(&moments, false);
    let thresholds = planes::thresholds(&filtered, &norm, input.filters.outlier_quantile);
    let costs = CostTerms::of_candidates(&k, &stats, &candidates, (w * h) as u32);
    let groups = image_level_groups(&candidates, MergeScope::PerPixel, None);
    let score = |chi: f32| {
        let mask = Image::filled(w, h, chi);
        image_level_scores(&input, &groups, &filtered, &norm, &costs, Some(&mask), None, &thresholds)
    };
    let (partial, full) = (score(0.2), score(1.0));
    let g = groups.iter().position(|g| (g.nu, g.connections) == (1.0, Some(1))).expect("a ν = 1, c = 1 group");
    assert_eq!(partial[g].cost, full[g].cost, "χ = 0.2 priced as merging always");
    let on = groups[g].variant(true, 0).unwrap();
    let judged = (w * h / 2) as f64 / (w * h) as f64;
    assert!((full[g].cost - costs[on].at(1.0) * judged).abs() < 1e-9 * full[g].cost, "{:?}", full[g]);
    // nowhere merging: the merge-off variant, without a map
    let off = groups[g].variant(false, 0).unwrap();
    assert!((score(0.0)[g].cost - costs[off].at(0.0) * judged).abs() < 1e-9 * full[g].cost);
    // merging in one pixel only: the map is built, and every judged pixel pays for it
    let mut one = Image::filled(w, h, 0.0);
    one.data[w * h - 1] = 1.0;
    let with_map = image_level_scores(&input, &groups, &filtered, &norm, &costs, Some(&one), None, &thresholds)[g].cost;
    let expected =
        (costs[off].at(0.0) + costs[on].build()) * (judged - 1.0 / (w * h) as f64) + costs[on].at(1.0) / (w * h) as f64;
    assert!((with_map - expected).abs() < 1e-9 * expected, "{with_map} vs {expected}");
}

/// Moments with heavy tails, +∞ flags and zeros, `k` candidates (the VCM ones first, path
/// tracing for the rest), on an image with black pixels, over more than one filter strip.
fn random_input(k: usize, seed: u64) -> (Vec<Candidate>, MomentBuffer, Image) {
    let (w, h) = (70u32, 23u32);
    let mut s = crate::sampler::Sampler::for_pixel(seed, 0, 0);
    let all = CandidateConfig::vcm().candidates();
    let candidates: Vec<Candidate> = (0..k).map(|c| all[c.min(all.len() - 1)]).collect();
    let mut moments = MomentBuffer::new(w, h, k);
    for v in moments.sums.iter_mut() {
        let u = s.next_1d();
        *v = match u {
            u if u < 0.0002 => f32::INFINITY,
            u if u < 0.05 => 0.0,
            u => (0.02 / u).powi(3),
        };
    }
    moments.iterations = 3;
    let image = Image::from_data(
        w as usize,
        h as usize,
        (0..w * h).map(|p| if p % 17 == 0 { 0.0 } else { 0.2 + s.next_1d() }).collect(),
    );
    (candidates, moments, image)
}

/// The optimiser's moment planes (transposed by tiles, shared outliers by index, filtered in
/// place with the thresholds streamed) equal the definitions in the module documentation bit
/// for bit: one image per candidate, the shared minimum's outliers by a full sort, the box
/// filter of [`super::filter_moments`] and the histogram quantile counted over every pixel.
#[test]
fn moment_planes_equal_the_definitions_bit_for_bit() {
    let (candidates, moments, image) = random_input(9, 3);
    let (w, h, k) = (image.width, image.height, candidates.len());
    let norm: Vec<f32> = image.data.iter().map(|&i| i * i + 1e-4).collect();
    let scale = 1.0 / moments.iterations as f32;
    let plane = |c: usize| -> Image {
        let v = (0..w * h).map(|p| moments.sums[p * k + c]).map(|v| if v.is_finite() { v * scale } else { v });
        Image::from_data(w, h, v.collect())
    };
    for outliers in [OutlierStage::Filtered, OutlierStage::Shared] {
        let mut expected: Vec<Image> = (0..k).map(plane).collect();
        if outliers == OutlierStage::Shared {
            let shared: Vec<f32> = (0..w * h)
                .map(|p| expected.iter().map(|e| e.data[p]).filter(|v| v.is_finite()).fold(f32::INFINITY, f32::min))
                .collect();
            let mut relative: Vec<f32> =
                shared.iter().zip(&norm).map(|(s, n)| s / n).filter(|v| v.is_finite()).collect();
            relative.sort_by(f32::total_cmp);
            let rank = ((0.999 * relative.len() as f64).ceil() as usize).clamp(1, relative.len()) - 1;
            for p in (0..w * h).filter(|&p| shared[p].is_finite() && shared[p] / norm[p] > relative[rank]) {
                for e in expected.iter_mut().filter(|e| e.data[p].is_finite()) {
                    e.data[p] = (e.data[p] - shared[p]).max(0.0);
                }
            }
        }
        let expected: Vec<Image> = expected.iter().map(|e| super::filter_moments(e, &norm, 3)).collect();
        let (mut got, minimum) = planes::moment_planes(&moments, outliers == OutlierStage::Shared);
        if let Some(minimum) = minimum {
            planes::subtract_shared_outliers(&mut got.slices_mut(), &minimum, &norm, 0.999);
        }
        let thresholds = planes::filter_planes(&mut got, &norm, 3, 0.999);
        assert_eq!(got.to_images(), expected, "{outliers:?}");
        let by_counts = planes::thresholds(&planes::Planes::from_images(&expected), &norm, 0.999);
        assert_eq!(thresholds.map_bits(), by_counts.map_bits(), "{outliers:?}");
    }
}

trait Bits {
    fn map_bits(&self) -> Vec<u32>;
}

impl Bits for Vec<f32> {
    fn map_bits(&self) -> Vec<u32> {
        self.iter().map(|v| v.to_bits()).collect()
    }
}

/// The image-level sums (in runs of pixels that merge alike, terms computed per block) and
/// the pixel level's merge bits equal the per-pixel definitions bit for bit, with a mask whose
/// χ lies on both sides of 0.1, black pixels, outliers and +∞ moments, per pixel and global.
#[test]
fn image_and_pixel_levels_equal_the_per_pixel_definitions_bit_for_bit() {
    let (candidates, moments, image) = random_input(51, 5);
    let (w, h, k) = (image.width, image.height, candidates.len());
    let norm: Vec<f32> = image.data.iter().map(|&i| i * i + 1e-4).collect();
    let stats = PathStatistics { camera_vertices: 4.0, light_vertices: 3.0, photons_per_query_per_path: 2e-6 };
    let constants = CostConstants::default();
    let costs = CostTerms::of_candidates(&constants, &stats, &candidates, (w * h) as u32);
    let (filtered, _) = planes::moment_planes(&moments, false);
    let thresholds = planes::thresholds(&filtered, &norm, 0.999);
    let mut s = crate::sampler::Sampler::for_pixel(8, 0, 0);
    let mask = Image::from_data(w, h, (0..w * h).map(|p| if p % 40 < 15 { 0.0 } else { 0.2 * s.next_1d() }).collect());
    for scope in [MergeScope::PerPixel, MergeScope::Global] {
        let input = OptimizerInput {
            restart_share: 0.0,
            incumbent: None,
            candidates: &candidates,
            moments: &moments,
            image: &image,
            statistics: stats,
            constants,
            filters: FilterSettings::default(),
            merge_scope: scope,
            connection_scope: ConnectionScope::Image,
        };
        let groups = image_level_groups(&candidates, scope, None);
        let pixel_mask = (scope == MergeScope::PerPixel).then_some(&mask);
        let got = image_level_scores(&input, &groups, &filtered, &norm, &costs, pixel_mask, None, &thresholds);
        assert!(got.iter().filter(|s| s.relative_moment.is_finite()).count() > groups.len() / 2);
        for (g, score) in groups.iter().zip(&got) {
            // the definition: one pass over the pixels per group
            let map_built = g.merge.is_none() && mask.data.iter().any(|&chi| chi > 0.1);
            let shared_build = match (map_built, g.variant(true, 0)) {
                (true, Some(on)) if candidates[on].merge => costs[on].build(),
                _ => 0.0,
            };
            let (mut rel, mut cost) = (0.0f64, 0.0f64);
            for (p, (&i, &n)) in image.data.iter().zip(&norm).enumerate() {
                let i = i as f64;
                if i == 0.0 {
                    continue;
                }
                let chi = g.merge.map_or(mask.data[p], |m| m as u8 as f32) as f64;
                let Some(c) = g.variant(chi > 0.1, 0) else { continue };
                let merges = candidates[c].merge;
                cost += (costs[c].at(merges as u8 as f64) + if merges { 0.0 } else { shared_build }) / (w * h) as f64;
                let mut moment = filtered[c][p];
                if moment / n > thresholds[c] && moment.is_finite() {
                    moment = 0.0;
                }
                rel += moment as f64 * (1.0 / ((i * i + 1e-4) * (w * h) as f64));
            }
            assert_eq!((score.relative_moment.to_bits(), score.cost.to_bits()), (rel.to_bits(), cost.to_bits()));
        }
        // the merge bits: per pixel, the first candidate with the lowest value
        let winners = pixel_winners(&input, &filtered, &costs);
        let bits: Vec<f32> = winners.iter().map(|w| w.is_some_and(|c| candidates[c].merge) as u8 as f32).collect();
        for (p, bit) in bits.iter().enumerate() {
            let mut best = (f64::INFINITY, None);
            for c in 0..k {
                let v = filtered[c][p] as f64 * costs[c].at(candidates[c].merge as u8 as f64);
                if v < best.0 {
                    best = (v, Some(c));
                }
            }
            let expected = matches!(best, (v, Some(c)) if v > 0.0 && candidates[c].merge) as u8 as f32;
            assert_eq!(bit.to_bits(), expected.to_bits(), "pixel {p}");
        }
    }
}

/// `OutlierStage::Each`: each candidate loses its own worst 0.1 % of pixels (relative
/// moments, before the filter), whatever the other candidates hold there; +∞ flags stay.
#[test]
fn each_candidate_loses_its_own_worst_pixels() {
    let (w, h) = (100usize, 20usize);
    let norm: Vec<f32> = (0..w * h).map(|p| if p % 2 == 0 { 1.0 } else { 4.0 }).collect();
    // candidate 0: one huge pixel (7) and one +∞; candidate 1: two huge pixels (3 and 11)
    let mut planes = vec![Image::filled(w, h, 1.0), Image::filled(w, h, 1.0)];
    planes[0].data[7] = 1e6;
    planes[0].data[8] = f32::INFINITY;
    planes[1].data[3] = 1e5;
    planes[1].data[11] = 1e7;
    remove_each_outliers(&mut planes, &norm, 0.999);
    // 2000 pixels: the 0.1 % above the 99.9 % quantile are the top two of each
    assert_eq!((planes[0].data[7], planes[0].data[8]), (0.0, f32::INFINITY));
    assert_eq!((planes[1].data[3], planes[1].data[11]), (0.0, 0.0));
    // the rest is untouched, the pixels of the other candidate's outliers included
    assert_eq!((planes[0].data[3], planes[0].data[11], planes[1].data[7]), (1.0, 1.0, 1.0));
    assert_eq!(
        planes.iter().flat_map(|p| &p.data).filter(|&&v| v == 1.0).count(),
        2 * w * h - 4,
        "three zeroed, one +∞"
    );
}

#[path = "connection_tests.rs"]
mod connection_tests;
