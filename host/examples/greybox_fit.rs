//! Physical parameters with confidence intervals from one log (`ferrosid::greybox`).
//!
//! ```text
//! cargo run --release -p ferrosid --example greybox_fit -- FILE.mat INPUT OUTPUT STRUCTURE [NAME=VALUE ...]
//! cargo run --release -p ferrosid --example greybox_fit -- \
//!     ../shared/data/motor-bench/MultisineTypeA.mat iq_refx omega_max two-mass Kt=1
//! ```
//! STRUCTURE: stage, stage-velocity, dc-motor, two-mass, two-mass-position; NAME=VALUE are the
//! known parameters (SI units). Prints the start mapped from the black-box model, the fit
//! and every parameter with its 95 % interval.
use ferrosid::greybox::{fit, GreyBoxOptions, Structure};
use ferrosid::io::{read_mat, MatOptions};
use ferrosid::n4sid::ChannelSet;
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err("usage: greybox_fit FILE.mat INPUT OUTPUT STRUCTURE [NAME=VALUE ...]".into());
    }
    let path = Path::new(&args[0]);
    let log = read_mat(
        path,
        &MatOptions {
            inputs: vec![args[1].clone()],
            outputs: vec![args[2].clone()],
            ..MatOptions::default()
        },
    )?;
    let mut opts = GreyBoxOptions::new(Structure::parse(&args[3])?);
    for kv in &args[4..] {
        let (k, v) = kv
            .split_once('=')
            .ok_or("known parameters are NAME=VALUE")?;
        opts = opts.with_known(k, v.parse()?);
    }
    let (u, y) = (
        log.inputs[0].data.as_slice(),
        log.outputs[0].data.as_slice(),
    );
    let (ur, yr) = ([u], [y]);
    let (un, yn) = ([args[1].clone()], [args[2].clone()]);
    let data = ChannelSet {
        source: path,
        ts: log.ts,
        u: &ur,
        y: &yr,
        u_names: &un,
        y_names: &yn,
    };
    let t0 = Instant::now();
    let f = fit(&data, &opts)?;
    println!(
        "{} on {} ({} samples, {:.3} s)",
        opts.structure.name(),
        path.display(),
        u.len(),
        t0.elapsed().as_secs_f64()
    );
    println!("start (from the black-box poles/zeros): {:?}", f.start);
    println!(
        "NRMSE {:.4} (black box of the same order {:.4}); {} iterations, converged {}, cond {:.2e}",
        f.nrmse, f.black_box_nrmse, f.iterations, f.converged, f.condition
    );
    println!("intervals: {}", f.interval_method);
    for p in &f.parameters {
        match p.interval {
            Some([lo, hi]) => println!(
                "  {:>3} = {:.5e} {}  95 % [{:.5e}, {:.5e}]  ({})",
                p.name, p.value, p.unit, lo, hi, p.description
            ),
            None => println!(
                "  {:>3} = {:.5e} {}  {:?}  ({})",
                p.name, p.value, p.unit, p.status, p.description
            ),
        }
    }
    Ok(())
}
