//! `cloudgi slab`: reflectance and transmittance of a plane-parallel slab, as one JSON line, by
//! the reference transport (Monte Carlo, with standard errors) or by the diffusion discretisation
//! of eq. 4 with eq. 7 ([`crate::diffusion::slab`], by default after the δ-M transform with
//! f = g², `--forward-fraction 0`: the paper's scheme) or discrete-ordinates transport
//! ([`crate::transport::slab`]), both deterministic: standard errors 0.

use crate::diffusion::slab::{slab_forward_fraction, solve_slab_similar};
use crate::error::{Error, Result};
use crate::reference::slab::{slab, Incidence, SlabParams, SlabResult};
use clap::{Args, ValueEnum};

/// `--incidence`: clap's view of [`Incidence`] (clap stays in the CLI).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum IncidenceArg {
    /// A beam at normal incidence.
    Collimated,
    /// Uniform radiance from the whole upper hemisphere (cosine-weighted incident directions).
    Diffuse,
}

/// Method for the slab.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SlabMethod {
    /// Unbiased Monte Carlo transport.
    Reference,
    /// The finite-difference diffusion solve (eq. 4 with eq. 7) on a 1-D grid.
    Diffusion,
    /// Discrete-ordinates transport (δ-M, DSA-accelerated source iteration).
    Transport,
}

#[derive(Args, Debug)]
pub struct SlabArgs {
    /// Optical thickness τ of the slab.
    #[arg(long)]
    thickness: f64,
    /// Single-scattering albedo in [0, 1].
    #[arg(long)]
    albedo: f64,
    /// Henyey–Greenstein mean cosine, |g| < 1.
    #[arg(long, allow_negative_numbers = true)]
    g: f64,
    /// Illumination from above: a normal beam or uniform diffuse light.
    #[arg(long, value_enum)]
    incidence: IncidenceArg,
    /// Transport method.
    #[arg(long, value_enum, default_value = "reference")]
    method: SlabMethod,
    /// `reference`: photons (2 to 1e12; default 1,000,000).
    #[arg(long)]
    samples: Option<u64>,
    /// `diffusion`: forward fraction f of the δ-M similarity transform, 0 ≤ f < 1 (default g²,
    /// measured against adding-doubling in docs/budget.md); 0 is the paper's scheme exactly.
    #[arg(long)]
    forward_fraction: Option<f64>,
    /// `reference`: seed of the photon streams (default 0).
    #[arg(long)]
    seed: Option<u64>,
}

impl SlabArgs {
    /// The flags given that `self.method` does not read, each with the method that does.
    fn unused_flags(&self) -> Vec<(&'static str, &'static str)> {
        let reference = self.method == SlabMethod::Reference;
        let diffusion = self.method == SlabMethod::Diffusion;
        [
            ("--samples", "reference", self.samples.is_some() && !reference),
            ("--seed", "reference", self.seed.is_some() && !reference),
            ("--forward-fraction", "diffusion", self.forward_fraction.is_some() && !diffusion),
        ]
        .into_iter()
        .filter_map(|(flag, method, unused)| unused.then_some((flag, method)))
        .collect()
    }
}

/// Thickest slab `--method transport` meshes (optical depths): its layer count grows as τ.
const MAX_TRANSPORT_THICKNESS: f64 = 1e4;

pub fn run(a: SlabArgs) -> Result<()> {
    let p = SlabParams {
        thickness: a.thickness,
        albedo: a.albedo,
        g: a.g,
        incidence: match a.incidence {
            IncidenceArg::Collimated => Incidence::Collimated,
            IncidenceArg::Diffuse => Incidence::Diffuse,
        },
    };
    p.validate("command line")?;
    for (flag, method) in a.unused_flags() {
        note!(
            "warning: command line: `{flag}` does not apply to --method {}, only to --method {method}; it is ignored",
            a.method.to_possible_value().map_or_else(String::new, |v| v.get_name().to_string())
        );
    }
    let r = match a.method {
        SlabMethod::Reference => slab(&p, a.samples.unwrap_or(1_000_000), a.seed.unwrap_or(0))?,
        SlabMethod::Transport => {
            let s = crate::transport::slab::SlabSettings::default();
            if a.thickness > MAX_TRANSPORT_THICKNESS {
                return Err(Error::invalid(
                    "command line",
                    "--thickness",
                    format!(
                        "{} is too thick for --method transport: its mesh has layers of at most {} optical \
                         depths, so time grows with τ (1e4 takes about a minute, 1e30 would never end); \
                         use --method reference or diffusion, or at most {MAX_TRANSPORT_THICKNESS:e}",
                        a.thickness, s.max_layer
                    ),
                ));
            }
            let x = crate::transport::slab::solve_slab(a.thickness, a.albedo, a.g, p.incidence, &s);
            if !(x.change <= s.tolerance && x.r.is_finite() && x.t.is_finite() && x.r >= 0.0 && x.t >= 0.0) {
                let cause = if a.g < -0.9 {
                    format!(
                        ": its expansion of a phase function this strongly backwards (--g {}) makes the iteration unstable",
                        a.g
                    )
                } else {
                    String::new()
                };
                return Err(Error::Numerical {
                    stage: "slab --method transport".into(),
                    message: format!(
                        "the iteration gave no physical result (R {:.3e}, T {:.3e}, relative change {:.1e} after \
                         {} iterations, tolerance {:.0e}){cause}; use --method reference, or diffusion",
                        x.r, x.t, x.change, x.iterations, s.tolerance
                    ),
                });
            }
            SlabResult {
                r: x.r,
                t: x.t,
                r_stderr: 0.0,
                t_stderr: 0.0,
            }
        }
        SlabMethod::Diffusion => {
            let f = a.forward_fraction.unwrap_or_else(|| slab_forward_fraction(a.g));
            if !(0.0..1.0).contains(&f) {
                return Err(Error::invalid(
                    "command line",
                    "--forward-fraction",
                    format!("{f} is outside [0, 1); give a fraction such as 0.81 (g²) or 0 for the paper's scheme"),
                ));
            }
            solve_slab_similar(a.thickness, a.albedo, a.g, f, p.incidence)
        }
    };
    let line = serde_json::to_string(&r).map_err(|e| Error::format("<json>", e.to_string()))?;
    super::console::print(&format!("{line}\n"))?;
    Ok(())
}
