//! The generated module's compensation block (`flashed::COMPENSATION`, plain data of the
//! generated file) mapped to the firmware's control types. Shared by the `closedloop` and
//! `powerup` images (`#[path]` module: the generated types exist per image, in its `flashed`
//! module).
use super::flashed;
use ferrosid_firmware::control::{
    AntiWindup, BacklashInverse, CompensationConfig, DeadZoneInverse, FrictionFeedforward,
    LagAware, VelocitySource,
};

/// The generated compensation in the firmware's form (`None` when absent or disabled).
pub fn compensation_config() -> Option<CompensationConfig> {
    let c = flashed::COMPENSATION.filter(|c| c.enabled)?;
    Some(CompensationConfig {
        friction_feedforward: c.friction_feedforward.map(|f| FrictionFeedforward {
            coulomb: f.coulomb,
            viscous: f.viscous,
            smoothing_velocity: f.smoothing_velocity,
            velocity: match f.velocity {
                flashed::VelocitySource::Output => VelocitySource::Output,
                flashed::VelocitySource::OutputDifference { alpha, .. } => {
                    VelocitySource::OutputDifference { alpha }
                }
                flashed::VelocitySource::Reference => VelocitySource::Reference,
            },
            lag_aware: f.lag_aware.map(|l| LagAware {
                pole: l.pole,
                prediction_s: l.prediction_s,
                stick_band: l.stick_band,
            }),
        }),
        dead_zone_inverse: c.dead_zone_inverse.map(|d| DeadZoneInverse {
            width: d.width,
            smoothing: d.smoothing,
        }),
        backlash_inverse: c.backlash_inverse.map(|b| BacklashInverse {
            gap: b.gap,
            smoothing: b.smoothing,
        }),
        anti_windup: c.anti_windup.map(|a| AntiWindup {
            u_min: a.u_min,
            u_max: a.u_max,
            gain: a.gain,
        }),
    })
}
