use super::query::{closest_point_on_ellipsoid, PlacedEllipsoid, Prepared};
use super::solve::{closest_sorted, solve_secular, solve_secular_lanes, LANES};
use super::sorted::SortedPlacement;
use super::stream::{self, Kernel};
use crate::simd::Arch;
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;

/// Brute force: the nearest of a dense parametric sampling, refined by a local
/// search on the sphere parameters.
fn brute_force(e: &Vector3<f64>, y: &Vector3<f64>) -> f64 {
    let point = |th: f64, ph: f64| {
        Vector3::new(
            e.x * th.sin() * ph.cos(),
            e.y * th.sin() * ph.sin(),
            e.z * th.cos(),
        )
    };
    let n = 200;
    let mut best = (f64::INFINITY, 0.0, 0.0);
    for i in 0..=n {
        let th = std::f64::consts::PI * i as f64 / n as f64;
        for j in 0..2 * n {
            let ph = std::f64::consts::PI * j as f64 / n as f64;
            let d = (point(th, ph) - y).norm();
            if d < best.0 {
                best = (d, th, ph);
            }
        }
    }
    // Pattern search refinement.
    let mut step = std::f64::consts::PI / n as f64;
    while step > 1e-12 {
        let mut improved = false;
        for (dt, dp) in [(step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)] {
            let (th, ph) = (best.1 + dt, best.2 + dp);
            let d = (point(th, ph) - y).norm();
            if d < best.0 {
                best = (d, th, ph);
                improved = true;
            }
        }
        if !improved {
            step *= 0.5;
        }
    }
    best.0
}

fn check(e: Vector3<f64>, y: Vector3<f64>) {
    let r = closest_point_on_ellipsoid(&e, &y);
    let bf = brute_force(&e, &y);
    assert!(
        (r.distance.abs() - bf).abs() < 1e-5,
        "e={e:?} y={y:?}: {} vs brute force {bf}",
        r.distance
    );
    // On the surface, and y = x + d·n.
    let level = (r.closest.component_div(&e)).norm_squared();
    assert!(
        (level - 1.0).abs() < 1e-9,
        "closest not on surface: {level}"
    );
    assert!((r.normal.norm() - 1.0).abs() < 1e-9);
    if r.distance.abs() > 1e-9 {
        assert!((r.closest + r.normal * r.distance - y).norm() < 1e-8);
    }
    let inside = (y.component_div(&e)).norm_squared() < 1.0;
    assert_eq!(inside, r.distance < 0.0);
}

#[test]
fn special_cases() {
    let e = Vector3::new(0.3, 0.1, 0.05);
    check(e, Vector3::new(0.0, 0.0, 0.0));
    check(e, Vector3::new(0.1, 0.0, 0.0));
    check(e, Vector3::new(0.0, 0.02, 0.0));
    check(e, Vector3::new(0.0, 0.0, 0.01));
    check(e, Vector3::new(0.25, 0.05, 0.0));
    check(e, Vector3::new(5.0, 0.0, 0.0));
    check(e, Vector3::new(-3.0, 7.0, -2.0));
    check(e, Vector3::new(0.3, 0.0, 0.0));
    // Near-spherical and flat.
    check(Vector3::new(0.1, 0.1, 0.1), Vector3::new(0.02, -0.01, 0.03));
    check(Vector3::new(0.1, 0.1, 0.1), Vector3::new(0.0, 0.0, 0.0));
    check(
        Vector3::new(0.1, 0.1 + 1e-12, 0.1),
        Vector3::new(0.3, 0.2, -0.1),
    );
    check(Vector3::new(0.2, 0.2, 0.001), Vector3::new(0.05, 0.05, 0.0));
    check(
        Vector3::new(0.2, 0.2, 0.001),
        Vector3::new(0.05, 0.05, 1e-7),
    );
    check(
        Vector3::new(0.2, 0.15, 0.001),
        Vector3::new(0.15, 0.1, 1e-300),
    );
    check(Vector3::new(0.05, 0.4, 0.05), Vector3::new(1e-9, 0.0, 1e-9));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]
    #[test]
    fn matches_brute_force(
        ex in 0.02f64..0.4, ey in 0.02f64..0.4, ez in 0.02f64..0.4,
        px in -1.0f64..1.0, py in -1.0f64..1.0, pz in -1.0f64..1.0, scale in 0.05f64..2.0,
    ) {
        let e = Vector3::new(ex, ey, ez);
        // Mix points near the surface and far away.
        let y = Vector3::new(px, py, pz).component_mul(&e) * (2.0 * scale);
        check(e, y);
    }
}

/// Independent reference: plain bisection on F(t) = Σ (e_i y_i / (t + e_i²))² − 1
/// over (−e_min², |y|·e_max], run until the bracket cannot shrink any more (every
/// f64 between the ends is tried), for points off the coordinate planes.
fn bisection_reference(e: &Vector3<f64>, y: &Vector3<f64>) -> f64 {
    let f = |t: f64| {
        (0..3)
            .map(|i| (e[i] * y[i] / (t + e[i] * e[i])).powi(2))
            .sum::<f64>()
            - 1.0
    };
    let e_min2 = e.min() * e.min();
    let (mut lo, mut hi) = (-e_min2, y.norm() * e.max());
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let t = 0.5 * (lo + hi);
    let x = Vector3::from_fn(|i, _| e[i] * e[i] * y[i] / (t + e[i] * e[i]));
    let d = (y - x).norm();
    if y.component_div(e).norm_squared() < 1.0 {
        -d
    } else {
        d
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    /// The hot-loop path (axis sort folded into the rotation, distance-only and
    /// distance + normal variants, the lower bound) against the bisection reference.
    #[test]
    fn sorted_placement_matches_reference(
        ex in 0.01f64..0.4, ey in 0.01f64..0.4, ez in 0.01f64..0.4,
        flat in 0usize..4,
        px in -1.0f64..1.0, py in -1.0f64..1.0, pz in -1.0f64..1.0,
        scale in prop_oneof![0.001f64..0.5, 0.5f64..1.5, 1.5f64..40.0],
        angles in (-3.0f64..3.0, -1.5f64..1.5, -3.0f64..3.0),
    ) {
        // Include near-spherical, needle and pancake shapes.
        let e = match flat {
            0 => Vector3::new(ex, ey, ez),
            1 => Vector3::new(ex, ex * (1.0 + 1e-9), ex),
            2 => Vector3::new(ex, ey, 1e-3 * ez),
            _ => Vector3::new(ex, 1e-2 * ey, 1e-2 * ey),
        };
        prop_assume!(px.abs() > 1e-3 && py.abs() > 1e-3 && pz.abs() > 1e-3);
        let y = Vector3::new(px, py, pz).component_mul(&e) * scale;
        let reference = bisection_reference(&e, &y);
        let rot = nalgebra::Rotation3::from_euler_angles(angles.0, angles.1, angles.2);
        let placed = PlacedEllipsoid {
            centre: Vector3::new(0.3, -0.2, 2.5),
            rotation: *rot.matrix(),
            prepared: Prepared::new(&e),
        };
        let p = placed.rotation * y + placed.centre;
        let fast = SortedPlacement::new(&placed);
        let pa = [p.x, p.y, p.z];
        let d = fast.signed_distance(&pa);
        let tol = 1e-9 * (1.0 + y.norm());
        prop_assert!((d - reference).abs() < tol, "{d} vs reference {reference}");
        let (d2, n) = fast.distance_and_normal(&pa);
        prop_assert_eq!(d, d2);
        let q = placed.query(&p);
        prop_assert!((q.distance - d).abs() < 1e-12 * (1.0 + y.norm()));
        let n = Vector3::new(n[0], n[1], n[2]);
        prop_assert!((n - q.normal).norm() < 1e-9);
        let lower = fast.distance_lower_bound(&fast.local(&pa));
        // Relative slack: on a near-sphere the sphere bound *is* the distance, and
        // the two round differently (by a few units in the last place).
        prop_assert!(lower >= 0.0 && lower <= d.abs() * (1.0 + 1e-11) + 1e-12, "{lower} > {d}");
        // The square-root-free test agrees with the bound, away from rounding ties
        // (whose width scales with the coordinates, not with t).
        let yl = fast.local(&pa);
        let tie = 1e-12 * (1.0 + y.norm());
        for t in [-0.1, 0.0, 0.5 * lower, lower * (1.0 - 1e-9), lower * (1.0 + 1e-9), 2.0 * lower + 0.01] {
            if t <= 0.0 || (lower - t).abs() > tie * (1.0 + t) {
                prop_assert_eq!(fast.is_beyond(&fast.beyond(t), &yl), lower >= t, "t {}", t);
            }
            // The same with the division by e_min as a multiplication (t > 0).
            if t > 0.0 && (lower - t).abs() > tie * (1.0 + t) {
                prop_assert_eq!(fast.lower_bound_passes(&yl, t), lower >= t, "t {}", t);
            }
        }
        prop_assert!(!fast.lower_bound_passes(&yl, f64::INFINITY));
        // Many points at once: the same local coordinates and test, bit for bit.
        let cloud: Vec<[f64; 3]> = (0..11)
            .map(|k| {
                let f = 0.3 * k as f64 - 1.5;
                [pa[0] + f * 0.1, pa[1] - f * f * 0.05, pa[2] + f * 0.07]
            })
            .collect();
        let coord = |r: usize| cloud.iter().map(|p| p[r]).collect::<Vec<f64>>();
        let (cx, cy, cz) = (coord(0), coord(1), coord(2));
        let mut local = [vec![0.0; 11], vec![0.0; 11], vec![0.0; 11]];
        let mut beyond = vec![false; 11];
        let b = fast.beyond(0.5 * lower + 0.01);
        let [l0, l1, l2] = &mut local;
        fast.locals_beyond(&b, [&cx, &cy, &cz], [l0, l1, l2], &mut beyond);
        for (i, p) in cloud.iter().enumerate() {
            let y = fast.local(p);
            prop_assert_eq!([local[0][i], local[1][i], local[2][i]], y);
            prop_assert_eq!(beyond[i], fast.is_beyond(&b, &y));
        }
        // The batched queries (lockstep lanes, and the scalar tail) give the same
        // distance and normal, whichever lane (or the tail) the point takes.
        let (d2, n2) = fast.distance_and_normal(&pa);
        let y_local = fast.local(&pa);
        let others = [[0.05, 0.1, -0.2], [-0.3, 0.02, 0.01], [0.2, -0.2, 0.4]];
        for slot in 0..=LANES {
            // `slot` points before it, then enough to fill the lanes: it sits in
            // lane `slot`, or (slot = LANES) alone in the tail.
            let mut items: Vec<[f64; 3]> = others.iter().cycle().take(slot).copied().collect();
            items.push(y_local);
            items.extend(others.iter().cycle().take(LANES.saturating_sub(slot + 1)));
            let mut got = None;
            fast.distances_and_normals_batched(
                items.iter().copied().enumerate(),
                |i, dd, nn| if i == slot { got = Some((dd, nn)) },
            );
            prop_assert_eq!(got, Some((d2, n2)));
            let mut got = None;
            fast.signed_distances_batched(items.iter().copied().enumerate(), |i, dd| {
                if i == slot {
                    got = Some(dd)
                }
            });
            prop_assert_eq!(got, Some(d2));
        }
    }
}

/// The lockstep root-finder gives, lane by lane, bit for bit what the scalar
/// `solve_secular` gives, over ellipsoids from near-spherical to flat and points inside,
/// near and far.
#[test]
fn root_finder_lanes_agree_bit_for_bit() {
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..400 {
        let radii = Vector3::new(0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd());
        let placed = PlacedEllipsoid {
            centre: Vector3::zeros(),
            rotation: Matrix3::identity(),
            prepared: Prepared::new(&radii),
        };
        let fast = SortedPlacement::new(&placed);
        let c = &fast.sorted;
        let scale = [0.01, 0.3, 1.0, 3.0][(rnd() * 4.0) as usize];
        let mut sa = [[0.0; 3]; LANES];
        let (mut lo, mut hi) = ([0.0; LANES], [0.0; LANES]);
        for l in 0..LANES {
            let y = [rnd() * scale, rnd() * scale, (rnd() * scale).max(1e-9)];
            (sa[l], lo[l], hi[l]) = c.secular_setup(&y);
        }
        let lanes = solve_secular_lanes(&sa, &c.b, lo, hi);
        for l in 0..LANES {
            let scalar = solve_secular(&sa[l], &c.b, lo[l], hi[l]);
            assert_eq!(lanes[l].to_bits(), scalar.to_bits());
        }
    }
}

/// The batched distances and normals (through the stream with every instruction set
/// the CPU has) and
/// the lockstep ones give bit for bit the one-point values, over ellipsoids
/// from near-spherical to flat, points inside, near and far, on coordinate planes
/// and axes, batches that are not multiples of 8 and runs longer than one block.
#[test]
fn batched_closest_points_agree_bit_for_bit() {
    let archs = Arch::supported();
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for trial in 0..300 {
        let mut radii = Vector3::new(0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd());
        if trial % 7 == 0 {
            radii = Vector3::repeat(radii.x); // a sphere
        } else if trial % 7 == 1 {
            radii.y = radii.x; // a spheroid
        }
        let rot = nalgebra::Rotation3::from_euler_angles(rnd() * 3.0, rnd(), rnd() * 2.0);
        let e = SortedPlacement::new(&PlacedEllipsoid {
            centre: Vector3::new(rnd() - 0.5, rnd() - 0.5, 1.0 + 3.0 * rnd()),
            rotation: *rot.matrix(),
            prepared: Prepared::new(&radii),
        });
        let n = [1, 7, 8, 9, 100, 256, 257, 700][trial % 8];
        let scale = [0.01, 0.3, 1.0, 3.0][(rnd() * 4.0) as usize];
        let mut local = vec![[0.0; 3]; n];
        for y in local.iter_mut() {
            *y = [0.0; 3].map(|_| (2.0 * rnd() - 1.0) * scale);
            // Some points on coordinate planes and axes, and at the centre.
            match (rnd() * 12.0) as usize {
                0 => y[0] = 0.0,
                1 => y[1] = 0.0,
                2 => y[2] = 0.0,
                3 => (y[0], y[1]) = (0.0, 0.0),
                4 => (y[1], y[2]) = (0.0, 0.0),
                5 => *y = [0.0; 3],
                _ => {}
            }
        }
        // Every other point, in a shuffled order, as the callers pass subsets.
        let items = || {
            (0..n)
                .rev()
                .filter(|i| i % 2 == 0 || n < 9)
                .map(|i| (i, local[i]))
        };
        let mut seen = vec![0u32; n];
        let one_point = |i: usize| {
            let ys = local[i].map(f64::abs);
            let x = closest_sorted(&e.sorted, ys);
            (e.signed_from_closest(&ys, &x), e.normal_at(&local[i], &x))
        };
        e.distances_and_normals_batched(items(), |i, d, nrm| {
            let (d1, n1) = one_point(i);
            assert_eq!(d.to_bits(), d1.to_bits(), "trial {trial} point {i}");
            assert_eq!(nrm.map(f64::to_bits), n1.map(f64::to_bits));
            seen[i] += 1;
        });
        e.signed_distances_batched(items(), |i, d| {
            assert_eq!(d.to_bits(), e.signed_distance_local(&local[i]).to_bits());
            seen[i] += 1;
        });
        e.closest_lockstep(items(), |i, _, ys, x| {
            assert_eq!(
                e.signed_from_closest(ys, x).to_bits(),
                one_point(i).0.to_bits()
            );
            seen[i] += 1;
        });
        // The stream with every instruction set this CPU has, whichever the process
        // chose.
        for &arch in &archs {
            e.streamed::<true>(arch, items(), |i, d, nrm| {
                let (d1, n1) = one_point(i);
                assert_eq!(d.to_bits(), d1.to_bits(), "trial {trial} point {i}");
                assert_eq!(nrm.map(f64::to_bits), n1.map(f64::to_bits));
                seen[i] += 1;
            });
            e.streamed::<false>(arch, items(), |i, d, _| {
                assert_eq!(d.to_bits(), one_point(i).0.to_bits());
                seen[i] += 1;
            });
        }
        let calls = 3 + 2 * archs.len() as u32;
        for (i, &s) in seen.iter().enumerate() {
            assert_eq!(s, if i % 2 == 0 || n < 9 { calls } else { 0 }, "point {i}");
        }
    }
    eprintln!("instruction sets compared: {archs:?}");
}

/// The single-precision block distances stay within 2e-6 m of the f64 distances of
/// the same (f32) points, over ellipsoids from near-spherical to flat and clouds
/// from the surface out to a few metres, up to 6 m from the camera.
#[test]
fn f32_block_distances_match_f64() {
    let mut seed = 0xD1B5_4A32_D192_ED03u64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut worst, mut compared, mut bounded) = (0.0f64, 0usize, 0usize);
    let archs = Arch::supported();
    let mut sets_compared = 0;
    for trial in 0..400 {
        let mut radii = Vector3::new(0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd());
        if trial % 7 == 0 {
            radii = Vector3::repeat(radii.x);
        } else if trial % 7 == 1 {
            radii.y = radii.x;
        } else if trial % 7 == 2 {
            radii.z = 0.005; // flat
        }
        let rot = nalgebra::Rotation3::from_euler_angles(rnd() * 3.0, rnd(), rnd() * 2.0);
        let centre = Vector3::new(2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0, 1.0 + 3.0 * rnd());
        let e = SortedPlacement::new(&PlacedEllipsoid {
            centre,
            rotation: *rot.matrix(),
            prepared: Prepared::new(&radii),
        });
        let n = [1, 15, 16, 17, 100, 256, 257, 700][trial % 8];
        let scale = [0.01, 0.1, 0.3, 1.0, 2.0][(rnd() * 5.0) as usize];
        let mut p = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        for i in 0..n {
            // Around the surface: a point of the surface direction scaled in or out.
            let dir = Vector3::new(2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0);
            let local =
                dir.component_mul(&radii) * (0.2 + 1.6 * rnd()) + dir.normalize() * scale * rnd();
            let q = centre + rot * local;
            for (c, v) in p.iter_mut().zip(q.iter()) {
                c[i] = *v as f32;
            }
        }
        let pts = [&p[0][..], &p[1], &p[2]];
        let mut out = vec![f32::NAN; n];
        e.signed_distances_camera_soa_f32(pts, None, &mut out);
        let mut lockstep = vec![f32::NAN; n];
        e.signed_distances_camera_lockstep_f32(pts, None, &mut lockstep);
        // With a cap: exact below it (the same values), the lower bound above.
        let cap = [0.01, 0.05, 0.3][trial % 3];
        let mut capped = vec![f32::NAN; n];
        e.signed_distances_camera_soa_f32(pts, Some(cap), &mut capped);
        let mut capped_lockstep = vec![f32::NAN; n];
        e.signed_distances_camera_lockstep_f32(pts, Some(cap), &mut capped_lockstep);
        // The single-precision stream gives the same bits with every instruction set the
        // CPU has, and the process's when that is a stream too.
        for &arch in &archs {
            for c in [None, Some(cap)] {
                let mut narrow = vec![f32::NAN; n];
                e.streamed_f32(arch, pts, c, &mut narrow);
                let reference = if c.is_some() { &capped } else { &out };
                if matches!(stream::kernel(), Kernel::Stream(_)) {
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&narrow), bits(reference), "trial {trial}, cap {c:?}");
                }
                for i in 0..n {
                    let q = [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64];
                    let exact = e.signed_distance(&q);
                    if c.is_none() || (narrow[i] as f64) < cap {
                        assert!((narrow[i] as f64 - exact).abs() <= 2e-6);
                    } else {
                        assert!(narrow[i] as f64 >= cap - 1e-6);
                        assert!(narrow[i] as f64 <= exact + 1e-6);
                    }
                }
                sets_compared += 1;
            }
        }
        for i in 0..n {
            let q = [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64];
            let exact = e.signed_distance(&q);
            let err = (out[i] as f64 - exact).abs();
            assert!(
                err <= 2e-6,
                "trial {trial} point {i}: {} vs {exact}",
                out[i]
            );
            assert!((lockstep[i] as f64 - exact).abs() <= 1e-6);
            worst = worst.max(err);
            compared += 1;
            for (c, full) in [(capped[i], out[i]), (capped_lockstep[i], lockstep[i])] {
                if (c as f64) < cap {
                    assert_eq!(c, full, "trial {trial} point {i} below the cap");
                } else {
                    assert!(c as f64 >= cap - 1e-6 && c <= full + 1e-6, "{c} vs {full}");
                    bounded += (c != full) as usize;
                }
            }
        }
    }
    assert!(
        bounded > 1000,
        "the cap's bounds were exercised on {bounded} values"
    );
    eprintln!("f32 distances: worst error {worst:.2e} m over {compared} points");
    eprintln!("f32 stream compared on {sets_compared} runs with {archs:?}");
}

#[test]
fn placed_matches_local_query() {
    let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
    let placed = PlacedEllipsoid {
        centre: Vector3::new(0.1, -0.2, 2.0),
        rotation: *rot.matrix(),
        prepared: Prepared::new(&Vector3::new(0.1, 0.25, 0.07)),
    };
    let p = Vector3::new(0.3, 0.1, 2.2);
    let r = placed.query(&p);
    let local = rot.inverse() * (p - placed.centre);
    let l = closest_point_on_ellipsoid(&Vector3::new(0.1, 0.25, 0.07), &local);
    assert!((r.distance - l.distance).abs() < 1e-12);
    assert!((r.closest + r.normal * r.distance - p).norm() < 1e-9);
}
