//! `cloudgi slab`: reflectance and transmittance of a plane-parallel slab by the diffusion
//! discretisation ([`cloudgi::diffusion::slab`]), alone or against an adding-doubling table.

use clap::{Args, ValueEnum};
use cloudgi::diffusion::slab::{default_cells, solve_slab, Incidence};
use cloudgi::error::{Error, Result};
use std::path::PathBuf;

/// Slab methods.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum SlabMethod {
    /// The finite-difference diffusion solve of eq. 4 with eq. 7.
    Diffusion,
}

/// Arguments of `cloudgi slab`.
#[derive(Args, Debug)]
pub struct SlabArgs {
    /// Method.
    #[arg(long, value_enum, default_value = "diffusion")]
    method: SlabMethod,
    /// Optical thickness (with --albedo and --g), unless --reference is given.
    #[arg(long)]
    tau: Option<f64>,
    /// Single-scattering albedo.
    #[arg(long, default_value_t = 0.99)]
    albedo: f64,
    /// Henyey-Greenstein g.
    #[arg(long, default_value_t = 0.0)]
    g: f64,
    /// Adding-doubling CSV (optical_thickness,albedo,g,UR1,UT1,URU,UTU): print a Markdown comparison table.
    #[arg(long)]
    reference: Option<PathBuf>,
}

fn check(tau: f64, a: f64, g: f64, what: &str) -> Result<()> {
    if !(tau.is_finite() && tau > 0.0) {
        return Err(Error::invalid(what, "--tau", format!("{tau} is not a positive optical thickness")));
    }
    if !(0.0..=1.0).contains(&a) {
        return Err(Error::invalid(what, "--albedo", format!("{a} is not in [0, 1]")));
    }
    if !(g.is_finite() && g.abs() < 1.0) {
        return Err(Error::invalid(what, "--g", format!("{g}: |g| must be below 1")));
    }
    Ok(())
}

/// Run the subcommand.
pub fn run(a: SlabArgs) -> Result<()> {
    let SlabMethod::Diffusion = a.method;
    if let Some(path) = &a.reference {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        println!(
            "| τ | a | g | (1−g)τ | UR1 ref | UR1 diff | UT1 ref | UT1 diff | URU ref | URU diff | UTU ref | UTU diff | max abs err |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for (ln, line) in text.lines().enumerate().skip(1) {
            let v: Vec<f64> = line
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<std::result::Result<_, _>>()
                .map_err(|e| Error::format(&file, format!("line {}: {e}", ln + 1)))?;
            if v.len() != 7 {
                return Err(Error::format(
                    &file,
                    format!("line {}: expected 7 columns, found {}", ln + 1, v.len()),
                ));
            }
            let (tau, al, g) = (v[0], v[1], v[2]);
            check(tau, al, g, &file)?;
            let n = solve_slab(tau, al, g, Incidence::Normal, default_cells(tau));
            let d = solve_slab(tau, al, g, Incidence::Diffuse, default_cells(tau));
            let err = [(n.r - v[3]).abs(), (n.t - v[4]).abs(), (d.r - v[5]).abs(), (d.t - v[6]).abs()]
                .into_iter()
                .fold(0.0, f64::max);
            println!(
                "| {tau} | {al} | {g} | {:.2} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
                (1.0 - g) * tau,
                v[3],
                n.r,
                v[4],
                n.t,
                v[5],
                d.r,
                v[6],
                d.t,
                err
            );
        }
        return Ok(());
    }
    let Some(tau) = a.tau else {
        return Err(Error::invalid(
            "command line",
            "--tau",
            "give --tau (with --albedo, --g) or --reference FILE",
        ));
    };
    check(tau, a.albedo, a.g, "command line")?;
    let n = solve_slab(tau, a.albedo, a.g, Incidence::Normal, default_cells(tau));
    let d = solve_slab(tau, a.albedo, a.g, Incidence::Diffuse, default_cells(tau));
    println!("normal beam:  R {:.6}  T {:.6}", n.r, n.t);
    println!("diffuse:      R {:.6}  T {:.6}", d.r, d.t);
    Ok(())
}
