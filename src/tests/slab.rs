//! The slab validator against adding-doubling: every one of the 105 rows of
//! `tests/data/slab_adding_doubling.csv` (copied from the project's shared reference data), for
//! both collimated and diffuse incidence, must agree within 3 standard errors + 0.002.
//!
//! Photons per case: `PHOTONS` gives a standard error of at most 0.5/√N ≈ 0.0022 for a fraction
//! near 0.5, so the tolerance (≤ 0.009) is tight enough to catch a wrong phase function sampler
//! (g = 0.9 treated as isotropic moves R by 0.1 or more at τ = 1), a missing unscattered beam or a
//! wrong diffuse-incidence distribution, while the whole table runs in a few seconds.

use crate::reference::slab::{slab, Incidence, SlabParams};

const PHOTONS: u64 = 50_000;

struct Row {
    tau: f64,
    albedo: f64,
    g: f64,
    ur1: f64,
    ut1: f64,
    uru: f64,
    utu: f64,
}

fn rows() -> Vec<Row> {
    super::common::slab_rows()
        .into_iter()
        .map(|v| Row {
            tau: v[0],
            albedo: v[1],
            g: v[2],
            ur1: v[3],
            ut1: v[4],
            uru: v[5],
            utu: v[6],
        })
        .collect()
}

#[test]
fn every_adding_doubling_row_within_three_standard_errors() {
    let rows = rows();
    assert_eq!(rows.len(), 105);
    let per_row = crate::par::map_range(rows.len(), &|i| {
        let r = &rows[i];
        [(Incidence::Collimated, r.ur1, r.ut1), (Incidence::Diffuse, r.uru, r.utu)]
            .into_iter()
            .filter_map(|(inc, er, et)| {
                let p = SlabParams {
                    thickness: r.tau,
                    albedo: r.albedo,
                    g: r.g,
                    incidence: inc,
                };
                let s = slab(&p, PHOTONS, 1000 + i as u64).unwrap();
                let ok_r = (s.r - er).abs() <= 3.0 * s.r_stderr + 0.002;
                let ok_t = (s.t - et).abs() <= 3.0 * s.t_stderr + 0.002;
                (!(ok_r && ok_t)).then(|| {
                    format!(
                        "τ={} a={} g={} {:?}: R {:.5}±{:.5} (exact {er}), T {:.5}±{:.5} (exact {et})",
                        r.tau, r.albedo, r.g, inc, s.r, s.r_stderr, s.t, s.t_stderr
                    )
                })
            })
            .collect::<Vec<String>>()
    });
    let failures = per_row.concat();
    assert!(
        failures.is_empty(),
        "{} of 210 cases fail:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn slab_is_deterministic_and_rejects_bad_input() {
    let p = SlabParams {
        thickness: 2.0,
        albedo: 0.9,
        g: 0.5,
        incidence: Incidence::Diffuse,
    };
    let a = slab(&p, 5000, 3).unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let b = pool.install(|| slab(&p, 5000, 3).unwrap());
    assert_eq!(a, b);
    // Conservative slab: nothing is absorbed.
    let c = slab(&SlabParams { albedo: 1.0, ..p }, 5000, 3).unwrap();
    assert!((c.r + c.t - 1.0).abs() < 1e-12);
    for bad in [
        SlabParams { thickness: -1.0, ..p },
        SlabParams { albedo: 1.5, ..p },
        SlabParams { g: 1.0, ..p },
        SlabParams { thickness: f64::NAN, ..p },
    ] {
        assert!(slab(&bad, 100, 0).is_err());
    }
    assert!(slab(&p, 1, 0).is_err());
    // A count past what any run finishes is refused with the bound, not allocated for.
    let e = slab(&p, u64::MAX, 0).unwrap_err().to_string();
    assert!(e.contains("--samples") && e.contains("1e12"), "{e}");
}
