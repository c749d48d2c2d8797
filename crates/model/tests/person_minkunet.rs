//! Person-MinkUNet end to end: U-Net stride bookkeeping on a voxelized simulated frame, overfitting
//! a few simulated frames (loss and AP@0.3), and a checkpoint round trip.

mod common;

use common::{ap03, head_tail, sim_batch, train, valid_gt};
use data_jrdb::Batch;
use model::person_minkunet::{HeadingEncoding, InputFeatures, Symmetry};
use model::{Detector, LossTerms, PersonMinkUNet, PersonMinkUNetConfig};
use sparse_conv::burn::module::Module;
use sparse_conv::burn::tensor::Device;

fn small() -> PersonMinkUNetConfig {
    PersonMinkUNetConfig { width: 0.25, ..Default::default() }
}

#[test]
fn local_input_features_place_each_point_inside_its_voxel() {
    let batch = sim_batch("local", 1, 8, 10.0, 5);
    let device = Device::flex();
    let x = PersonMinkUNet::input(&batch, InputFeatures::XyzLocal, &device);
    assert_eq!(x.channels(), 6);
    let f = x.features().into_data().try_to_vec::<f32>().unwrap();
    for row in 0..batch.num_voxels() {
        let (p, c) = (batch.point(row), batch.centre(row));
        for k in 0..3 {
            assert_eq!(f[6 * row + k], p[k], "raw channels first");
            let local = f[6 * row + 3 + k];
            assert!((-0.5001..=0.5001).contains(&local), "row {row}: {local} is outside its voxel");
            assert!((c[k] + local * batch.voxel_size[k] - p[k]).abs() < 1e-4, "row {row}: the point is the centre plus the local offset");
        }
    }
    let wrong = PersonMinkUNetConfig { input: InputFeatures::XyzLocal, ..small() };
    assert!(wrong.validate().unwrap_err().contains("in_channels = 3"));
    assert!(PersonMinkUNetConfig { in_channels: 6, ..wrong }.validate().is_ok());
}

#[test]
fn range_height_input_holds_no_direction() {
    let batch = sim_batch("range-height", 1, 8, 10.0, 5);
    let device = Device::flex();
    let x = PersonMinkUNet::input(&batch, InputFeatures::RangeHeight, &device);
    assert_eq!(x.channels(), 5);
    let f = x.features().into_data().try_to_vec::<f32>().unwrap();
    let local = PersonMinkUNet::input(&batch, InputFeatures::XyzLocal, &device).features().into_data().try_to_vec::<f32>().unwrap();
    for row in 0..batch.num_voxels() {
        let p = batch.point(row);
        assert!((f[5 * row] - (p[0] * p[0] + p[1] * p[1]).sqrt()).abs() < 1e-5, "row {row}: horizontal range");
        assert_eq!(f[5 * row + 1], p[2], "row {row}: height");
        assert_eq!(&f[5 * row + 2..5 * row + 5], &local[6 * row + 3..6 * row + 6], "row {row}: offsets inside the voxel as xyz_local's");
    }
    assert!(PersonMinkUNetConfig { in_channels: 5, input: InputFeatures::RangeHeight, ..small() }.validate().is_ok());
}

#[test]
fn weights_carried_to_a_wider_input_compute_the_same_boxes() {
    // xyz_local holds xyz's channels and three more: with the new channels' weights at zero, the
    // carried network's output is the trained one's.
    let batch = sim_batch("carry", 1, 8, 10.0, 5);
    let device = Device::flex();
    let cfg = small();
    let model = common::initialised(&device, Some(3), || cfg.init(&device));
    let before = model.head_output(&batch, &device);
    let carried = model.with_input(InputFeatures::XyzLocal);
    assert_eq!((carried.config.in_channels, carried.config.validate()), (6, Ok(())));
    let after = carried.head_output(&batch, &device);
    assert_eq!(before.len(), after.len());
    let worst = before.iter().zip(&after).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(worst < 1e-4, "outputs differ by {worst}");
    // Back to xyz: the same weights as at the start.
    let back = carried.with_input(InputFeatures::Xyz).head_output(&batch, &device);
    assert!(before.iter().zip(&back).all(|(a, b)| (a - b).abs() < 1e-4));
}

/// `batch` turned by 90° about the lattice's turn centre: voxel (i, j) → (−j − 1, i), its point and
/// centre turned about the centre, the rows in the same order.
fn turned(batch: &Batch) -> Batch {
    let [cx, cy] = PersonMinkUNet::turn_centre(batch.voxel_size);
    let turn = |xy: &mut [f32]| (xy[0], xy[1]) = (cx - (xy[1] - cy), cy + (xy[0] - cx));
    let mut out = batch.clone();
    out.coords.iter_mut().for_each(|c| *c = [c[0], -c[2] - 1, c[1], c[3]]);
    out.features.chunks_mut(3).for_each(turn);
    out.centres.chunks_mut(3).for_each(turn);
    out
}

#[test]
fn quarter_turn_symmetry_turns_the_boxes_with_the_cloud() {
    // With quarter-turn symmetry, the head's output on a turned cloud is its output on the cloud,
    // turned (offsets as vectors, the heading by whole bins), for every input and heading
    // encoding, after a few training steps have moved the weights and the norms' running
    // statistics away from their start. Without it the answers differ.
    let batch = sim_batch("turns", 1, 8, 10.0, 5);
    let device = Device::flex();
    let trained = |cfg: &PersonMinkUNetConfig| {
        let ad = Device::flex().autodiff();
        let model = common::initialised(&ad, Some(7), || cfg.init(&ad));
        train(model, &batch, &ad, 3, 1e-2).0.valid()
    };
    let off = |model: &PersonMinkUNet| {
        let (a, b) = (model.head_output(&batch, &device), model.head_output(&turned(&batch), &device));
        let expected = model.head_turn().apply(&a);
        assert_eq!(expected.len(), b.len());
        let scale = a.iter().fold(0f32, |m, v| m.max(v.abs()));
        expected.iter().zip(&b).map(|(e, b)| (e - b).abs()).fold(0f32, f32::max) / scale
    };
    let worst = |cfg: &PersonMinkUNetConfig| off(&trained(cfg));
    // Training mode too: batch statistics over the four copies, on the autodiff device.
    let ad = Device::flex().autodiff();
    let cfg = PersonMinkUNetConfig { symmetry: Symmetry::QuarterTurns, heading: HeadingEncoding::AxisFacing, ..small() };
    let model = common::initialised(&ad, Some(7), || cfg.init(&ad));
    let (a, b) = (model.head_output(&batch, &ad), model.head_output(&turned(&batch), &ad));
    let training = model.head_turn().apply(&a).iter().zip(&b).map(|(e, b)| (e - b).abs()).fold(0f32, f32::max);
    assert!(training < 1e-4, "with batch statistics the turned cloud's output is off by {training}");
    for (input, heading) in
        [(InputFeatures::Xyz, HeadingEncoding::AxisFacing), (InputFeatures::XyzLocal, HeadingEncoding::Bins), (InputFeatures::RangeHeight, HeadingEncoding::SinCos)]
    {
        let cfg = PersonMinkUNetConfig { symmetry: Symmetry::QuarterTurns, input, in_channels: input.channels(), heading, ..small() };
        let w = worst(&cfg);
        assert!(w < 1e-5, "{input:?} / {heading:?}: the turned cloud's output is off by {w} of the output's scale");
    }
    // Written out as a plain network (what inference runs), the same function.
    let model = trained(&cfg);
    let (tied, plain) = (model.head_output(&batch, &device), model.untied().head_output(&batch, &device));
    let untied = tied.iter().zip(&plain).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(untied < 1e-4, "the untied network differs by {untied}");
    // Weights carried to another input (`train.init` across inputs) keep the symmetry.
    let cfg = PersonMinkUNetConfig { symmetry: Symmetry::QuarterTurns, ..small() };
    let carried = off(&trained(&cfg).with_input(InputFeatures::XyzLocal));
    assert!(carried < 1e-5, "carried to xyz_local: off by {carried}");
    let plain = PersonMinkUNetConfig { heading: HeadingEncoding::AxisFacing, ..small() };
    assert!(worst(&plain) > 1e-2, "without symmetry a turn changes the answer");
}

#[test]
fn a_turned_head_row_decodes_to_the_turned_box() {
    // The head's turn (`head_turn`, which the network's output obeys) agrees with the box coder:
    // a row turned by it, decoded at the voxel turned about the sensor, is the box turned.
    use model::person_minkunet::BoxFrame;
    use rand::{Rng, SeedableRng};
    let device = Device::flex();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    for (heading, box_frame) in [
        (HeadingEncoding::Bins, BoxFrame::Base),
        (HeadingEncoding::AxisFacing, BoxFrame::Base),
        (HeadingEncoding::SinCos, BoxFrame::Base),
        (HeadingEncoding::AxisFacing, BoxFrame::Ray),
    ] {
        let model = PersonMinkUNetConfig { symmetry: Symmetry::QuarterTurns, heading, box_frame, ..small() }.init(&device);
        let (coder, turn) = (model.coder(), model.head_turn());
        for _ in 0..50 {
            let row: Vec<f32> = (0..coder.channels()).map(|_| rng.random_range(-1.0..1.0)).collect();
            let v = [rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0), rng.random_range(-1.0..1.0)];
            let a = coder.decode_row(&row, v);
            let b = coder.decode_row(&turn.apply(&row), [-v[1], v[0], v[2]]);
            let heading_off = (b.rot_z - a.rot_z - std::f64::consts::FRAC_PI_2).rem_euclid(std::f64::consts::TAU);
            let close = |x: f64, y: f64| (x - y).abs() < 1e-5;
            assert!(
                close(b.cx, -a.cy) && close(b.cy, a.cx) && close(b.cz, a.cz) && close(b.l, a.l) && close(b.w, a.w) && close(b.h, a.h),
                "{heading:?} {box_frame:?}: {b:?} is not {a:?} turned"
            );
            assert!(heading_off.min(std::f64::consts::TAU - heading_off) < 1e-4, "{heading:?} {box_frame:?}: heading {} is not {} + 90°", b.rot_z, a.rot_z);
        }
    }
}

#[test]
fn quarter_turn_symmetry_refuses_channels_it_cannot_split() {
    let turned = PersonMinkUNetConfig { symmetry: Symmetry::QuarterTurns, ..small() };
    assert!(turned.validate().is_ok());
    let narrow = PersonMinkUNetConfig { width: 0.2, ..turned.clone() };
    assert!(narrow.validate().unwrap_err().contains("divisible by 4"), "{:?}", narrow.validate());
    let bins = PersonMinkUNetConfig { num_bins: 10, ..turned };
    assert!(bins.validate().unwrap_err().contains("whole heading bins"), "{:?}", bins.validate());
}

#[test]
fn unet_levels_keep_their_coordinates() {
    let batch = sim_batch("unet", 2, 8, 10.0, 5);
    let device = Device::flex();
    let cfg = small();
    let model = common::initialised(&device, None, || cfg.init(&device));
    let input = PersonMinkUNet::input(&batch, cfg.input, &device);
    let levels = model.backbone.forward_levels(input);
    let cs = cfg.backbone().scaled_channels();
    let n = cfg.backbone().stages();
    assert_eq!(levels.down.len(), n + 1);
    assert_eq!(levels.up.len(), n);
    for (i, d) in levels.down.iter().enumerate() {
        assert_eq!(d.stride(), 1 << i, "down level {i}");
        assert_eq!(d.channels(), cs[i]);
        assert!(d.coords().iter().all(|c| (1..4).all(|k| c[k] % d.stride() == 0)), "level {i} is on its grid");
        if i > 0 {
            let prev = &levels.down[i - 1];
            assert!(d.num_voxels() < prev.num_voxels(), "each level is coarser");
            // Every coarse voxel is the floor of a finer voxel at twice the stride, and vice versa.
            let s = d.stride();
            let parents: std::collections::HashSet<[i32; 4]> =
                prev.coords().iter().map(|c| [c[0], c[1].div_euclid(s) * s, c[2].div_euclid(s) * s, c[3].div_euclid(s) * s]).collect();
            let coarse: std::collections::HashSet<[i32; 4]> = d.coords().iter().copied().collect();
            assert_eq!(parents, coarse);
        }
    }
    for (j, u) in levels.up.iter().enumerate() {
        let skip = &levels.down[n - 1 - j];
        assert_eq!(u.stride(), skip.stride(), "up level {j}");
        assert_eq!(u.coords(), skip.coords(), "up level {j} sits on down level {}'s voxels", n - 1 - j);
        assert_eq!(u.channels(), cs[n + 1 + j]);
    }
    let out = levels.up.last().unwrap();
    assert_eq!(&out.coords()[..], &batch.coords[..], "the output is on the input voxels, in order");
    assert_eq!(model.forward(&batch, &device).dims(), [batch.num_voxels(), 31]);
}

#[test]
fn overfits_simulated_frames_and_checkpoint_round_trips() {
    let batch = sim_batch("pmu-fit", 2, 16, 5.0, 11);
    assert!(valid_gt(&batch) >= 3, "the crop holds people: {}", valid_gt(&batch));
    let device = Device::flex().autodiff();
    // The paper's loss weighting (cls × 1): with the code's × 100 the regression needs far more
    // than a test-sized budget of steps to be fitted.
    let model = common::initialised(&device, Some(7), || PersonMinkUNetConfig { cls_weight: 1.0, ..small() }.init(&device));
    let (model, losses) = train(model, &batch, &device, 150, 4e-3);
    let (first, last) = head_tail(&losses, 5);
    eprintln!("Person-MinkUNet loss {first:.3} → {last:.3} on {} voxels", batch.num_voxels());
    assert!(losses.iter().all(|l| l.is_finite()));
    assert!(last < first / 8.0, "loss falls a lot: {first} → {last}");
    let eval_device = Device::flex();
    let model = model.valid();
    let dets = model.detect(&batch, &eval_device);
    let ap = ap03(&batch, &dets);
    eprintln!("AP@0.3 on the training frames: {ap:.3} ({} GT)", common::valid_gt(&batch));
    // Over initialisation seeds 0..=9 this budget gives 0.68 to 1.00 (median 0.87). The bound
    // leaves room for other CPUs' float paths (GEMM kernels differ between AVX2 and AVX-512),
    // which change the trajectory of 150 Adam steps.
    assert!(ap > 0.5, "AP@0.3 {ap}");

    let path = std::env::temp_dir().join(format!("pmunet-pmu-ckpt-{}", std::process::id()));
    model.clone().save_file(&path).unwrap();
    let fresh = PersonMinkUNetConfig { cls_weight: 1.0, ..small() }.init(&eval_device);
    assert_ne!(fresh.detect(&batch, &eval_device), dets, "a fresh model detects differently");
    let loaded = fresh.load_file(&path);
    assert_eq!(loaded.detect(&batch, &eval_device), dets, "identical detections after a round trip");
    // Burn writes `<path>.bpk`.
    let _ = std::fs::remove_file(path.with_extension("bpk"));
}

/// A small model with `heading` fitted for 150 steps on two simulated frames: its head's channel
/// count, the loss terms' names, the last term before and after, and the sorted heading errors
/// (degrees) of its decoded boxes against the frames' people.
fn fit_heading(name: &str, heading: HeadingEncoding) -> (usize, Vec<&'static str>, f32, f32, Vec<f64>) {
    let batch = sim_batch(name, 2, 16, 5.0, 11);
    let device = Device::flex().autodiff();
    let cfg = PersonMinkUNetConfig { cls_weight: 1.0, heading, ..small() };
    let model = common::initialised(&device, Some(7), || cfg.init(&device));
    let channels = model.coder().channels();
    let last_term = |l: &LossTerms| l.terms.last().unwrap().1.to_data().try_to_vec::<f32>().unwrap()[0];
    let first = model.loss(&batch, &device);
    let (names, before) = (first.terms.iter().map(|(n, _)| *n).collect(), last_term(&first));
    let (model, _) = train(model, &batch, &device, 150, 4e-3);
    let after = last_term(&model.loss(&batch, &device));
    let dets = model.valid().detect(&batch, &Device::flex());
    (channels, names, before, after, common::heading_errors(&batch, &dets))
}

/// The heading as a sine and cosine (`heading = "sin_cos"`): a 9-channel head whose heading term
/// is fitted on the training frames, and whose boxes decode the heading it learned.
#[test]
fn sin_cos_heading_is_fitted_and_decoded() {
    let (channels, names, before, after, errors) = fit_heading("pmu-sincos", HeadingEncoding::SinCos);
    assert_eq!(channels, 9);
    assert_eq!(names, ["cls", "loc", "dims", "heading"]);
    let median = errors[errors.len() / 2];
    eprintln!("sin/cos heading term {before:.3} → {after:.3}; median heading error {median:.1}° over {} people", errors.len());
    assert!(after < before / 4.0, "the heading term is fitted: {before} → {after}");
    assert!(median < 30.0, "the decoded heading follows the fitted one: median error {median}°");
}

/// The heading as an axis and a facing (`heading = "axis_facing"`): a `2·bins + 8`-channel head
/// whose facing term is fitted on the training frames, and whose boxes point the way it learned,
/// not only along the right axis.
#[test]
fn axis_and_facing_heading_is_fitted_and_decoded() {
    let (channels, names, before, after, errors) = fit_heading("pmu-facing", HeadingEncoding::AxisFacing);
    assert_eq!(channels, 32);
    assert_eq!(names, ["cls", "loc", "dims", "bin", "residual", "facing"]);
    let right = errors.iter().filter(|&&e| e < 90.0).count() as f64 / errors.len() as f64;
    let median = errors[errors.len() / 2];
    eprintln!("facing term {before:.3} → {after:.3}; median heading error {median:.1}°, {:.0} % within 90° over {} people", 100.0 * right, errors.len());
    assert!(after < before / 4.0, "the facing term is fitted: {before} → {after}");
    assert!(right > 0.8, "the decoded boxes point the fitted way: {:.0} % within 90°", 100.0 * right);
    assert!(median < 30.0, "and along the fitted axis: median error {median}°");
}
