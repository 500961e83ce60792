//! N4SID on the DaISy benchmark sets in ../shared/data/daisy (skipped with a notice when the
//! data are absent). Orders and in-sample free-run fits (x0 estimated) are pinned loosely here
//! and recorded for the side-by-side comparison with SLICOT and SIPPY.
mod n4sid_support;

use ferrosid::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use n4sid_support::*;

/// Input and output channels.
type Channels = (Vec<Vec<f64>>, Vec<Vec<f64>>);

fn load(rel: &str) -> Option<Channels> {
    let p = shared_data(rel)?;
    let cols = read_columns(&p);
    let h = cols.len() / 2;
    let u = cols[..h].iter().map(|c| demean(c)).collect();
    let y = cols[h..].iter().map(|c| demean(c)).collect();
    Some((u, y))
}

fn fits(r: &ferrosid::n4sid::N4sidResult, u: &[Vec<f64>], y: &[Vec<f64>]) -> Vec<f64> {
    let ysim = r.model.simulate(u, Some(&r.x0)).unwrap();
    y.iter()
        .zip(&ysim)
        .map(|(a, b)| fit_percent(a, b))
        .collect()
}

#[test]
fn robot_arm_is_fourth_order() {
    let Some((u, y)) = load("daisy/robot_arm.dat") else {
        return;
    };
    assert_eq!((u.len(), y.len(), u[0].len()), (1, 1, 1024));
    let r = n4sid_slices(1.0, &[&u[0]], &[&y[0]], &N4sidOptions::default()).unwrap();
    let fit = fits(&r, &u, &y);
    println!(
        "robot_arm: order {} fit {fit:?} ({})",
        r.order, r.order_reason
    );
    assert_eq!(r.order, 4, "{}", r.order_reason);
    assert!(fit[0] > 95.0, "fit {fit:?}");
    assert!(r.model.is_stable(0.0).unwrap());
    // Cross-validation: identify on the first 700 samples, validate on the last 324.
    let (ue, ye) = (&u[0][..700], &y[0][..700]);
    let re = n4sid_slices(
        1.0,
        &[ue],
        &[ye],
        &N4sidOptions {
            order: OrderSelection::Fixed(4),
            ..Default::default()
        },
    )
    .unwrap();
    let v = ferrosid::validate::simulation_fit(
        &re.model,
        &[&u[0][700..]],
        &[&y[0][700..]],
        ferrosid::validate::InitialState::Estimate,
    )
    .unwrap();
    println!(
        "robot_arm: order 4 on 0..700, validation fit on 700..1024: {:?}",
        v.fit_percent
    );
    assert!(v.fit_percent[0] > 80.0, "{:?}", v.fit_percent);
}

#[test]
fn cd_player_arm_two_by_two() {
    let Some((u, y)) = load("daisy/CD_player_arm.dat") else {
        return;
    };
    assert_eq!((u.len(), y.len(), u[0].len()), (2, 2, 2048));
    let ur: Vec<&[f64]> = u.iter().map(|c| c.as_slice()).collect();
    let yr: Vec<&[f64]> = y.iter().map(|c| c.as_slice()).collect();
    let r = n4sid_slices(1.0, &ur, &yr, &N4sidOptions::default()).unwrap();
    let fit = fits(&r, &u, &y);
    println!(
        "CD_player_arm: order {} fits {fit:?} warnings {:?} ({})",
        r.order, r.warnings, r.order_reason
    );
    assert!((2..=20).contains(&r.order));
    assert!(fit.iter().all(|&f| f > 75.0), "fits {fit:?}");
    assert!(r.model.is_stable(0.0).unwrap());
    // The classic low-order choice for comparisons with peers.
    let r8 = n4sid_slices(
        1.0,
        &ur,
        &yr,
        &N4sidOptions {
            order: OrderSelection::Fixed(8),
            ..Default::default()
        },
    )
    .unwrap();
    let fit8 = fits(&r8, &u, &y);
    println!("CD_player_arm: fixed order 8 fits {fit8:?}");
    assert!(fit8.iter().all(|&f| f > 70.0), "fits {fit8:?}");
}
