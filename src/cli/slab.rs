//! `cloudgi slab`: reflectance and transmittance of a plane-parallel slab by the reference
//! transport, as one JSON line.

use clap::{Args, ValueEnum};
use cloudgi::error::{Error, Result};
use cloudgi::reference::slab::{slab, Incidence, SlabParams};

/// Method for the slab (only the reference transport exists).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SlabMethod {
    /// Unbiased Monte Carlo transport.
    Reference,
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
    incidence: Incidence,
    /// Transport method.
    #[arg(long, value_enum, default_value = "reference")]
    method: SlabMethod,
    /// Photons.
    #[arg(long, default_value_t = 1_000_000)]
    samples: u64,
    /// Seed of the photon streams.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(a: SlabArgs) -> Result<()> {
    let p = SlabParams {
        thickness: a.thickness,
        albedo: a.albedo,
        g: a.g,
        incidence: a.incidence,
    };
    p.validate("command line")?;
    let SlabMethod::Reference = a.method;
    let r = slab(&p, a.samples, a.seed)?;
    let line = serde_json::to_string(&r).map_err(|e| Error::format("<json>", e.to_string()))?;
    println!("{line}");
    Ok(())
}
