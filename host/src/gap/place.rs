//! Where an unmodelled effect sits in the plant (the `place` of the gap report).
//!
//! | place | meaning |
//! |---|---|
//! | `drive` | in the command path before the plant dynamics (dead zone, input saturation, backlash at the input, input delay, actuator mode) |
//! | `motor` | friction on the driven (first or only) inertia or mass |
//! | `drivetrain` | between the two inertias of a two-mass structure (backlash in the shaft) |
//! | `load` | friction on the second (load) inertia of a two-mass structure |
//! | `state` | a level that saturates inside the plant |
//! | `sensor` | at the output (quantization, sensor clipping) |
//!
//! A place the data cannot tell apart from another (a pure delay or a series mode at the input
//! or the output of an LTI plant) is reported as `drive`. Effects compose in place order:
//! drive → plant (motor, drivetrain, load, state) → sensor ([`Place::order`]).
use super::effect::{Effect, EffectKind};
use std::fmt;

/// Where an effect acts (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Place {
    /// Command path before the plant dynamics.
    Drive,
    /// Friction on the driven (first or only) mass.
    Motor,
    /// Between the two inertias of a two-mass structure.
    Drivetrain,
    /// Friction on the load (second) inertia of a two-mass structure.
    Load,
    /// Saturating level inside the plant.
    State,
    /// At the output.
    Sensor,
}

impl Place {
    /// Every place, in signal order.
    pub const ALL: [Place; 6] = [
        Place::Drive,
        Place::Motor,
        Place::Drivetrain,
        Place::Load,
        Place::State,
        Place::Sensor,
    ];

    /// Report name (`drive`, `motor`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Place::Drive => "drive",
            Place::Motor => "motor",
            Place::Drivetrain => "drivetrain",
            Place::Load => "load",
            Place::State => "state",
            Place::Sensor => "sensor",
        }
    }

    /// Parses a report name.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|p| p.name() == s)
    }

    /// Position in the signal path: effects of a model are applied in increasing order
    /// (0 drive, 1 plant places, 2 sensor).
    pub fn order(self) -> u8 {
        match self {
            Place::Drive => 0,
            Place::Motor | Place::Drivetrain | Place::Load | Place::State => 1,
            Place::Sensor => 2,
        }
    }

    /// Whether the place needs a two-mass structure in the nominal model.
    pub fn needs_two_mass(self) -> bool {
        matches!(self, Place::Drivetrain | Place::Load)
    }
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The place an effect kind has when nothing else is said: friction on the motor, quantization
/// at the sensor, a state limit inside the plant, everything else in the drive.
pub fn default_place(kind: EffectKind) -> Place {
    match kind {
        EffectKind::CoulombFriction | EffectKind::Stiction => Place::Motor,
        EffectKind::Quantization => Place::Sensor,
        EffectKind::StateLimit | EffectKind::CurrentLimit => Place::State,
        _ => Place::Drive,
    }
}

/// Whether `kind` can act at `place` in the vocabulary.
pub fn allowed(kind: EffectKind, place: Place) -> bool {
    use EffectKind as K;
    match kind {
        K::CoulombFriction | K::Stiction => matches!(place, Place::Motor | Place::Load),
        K::Backlash => matches!(place, Place::Drive | Place::Drivetrain),
        K::Saturation => matches!(place, Place::Drive | Place::Sensor),
        K::Quantization => place == Place::Sensor,
        K::StateLimit | K::CurrentLimit => place == Place::State,
        K::Deadzone | K::TimeDelay | K::Resonance | K::SlewRate => place == Place::Drive,
    }
}

/// An effect with its place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedEffect {
    /// The effect and its parameters.
    pub effect: Effect,
    /// Where it acts.
    pub place: Place,
}

impl PlacedEffect {
    /// `effect` at its [`default_place`].
    pub fn at_default(effect: Effect) -> Self {
        Self {
            effect,
            place: default_place(effect.kind()),
        }
    }
}

impl fmt::Display for PlacedEffect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} @ {}", self.effect, self.place)
    }
}

/// A candidate to fit: an effect kind at a place.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Candidate {
    /// Effect kind.
    pub kind: EffectKind,
    /// Place.
    pub place: Place,
}

impl Candidate {
    /// `kind` at `place`.
    pub fn new(kind: EffectKind, place: Place) -> Self {
        Self { kind, place }
    }
}

impl fmt::Display for Candidate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}@{}", self.kind, self.place)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_defaults_are_allowed() {
        for p in Place::ALL {
            assert_eq!(Place::from_name(p.name()), Some(p));
        }
        for k in EffectKind::ALL {
            assert!(allowed(k, default_place(k)), "{k}");
        }
        assert!(!allowed(EffectKind::Quantization, Place::Drive));
        assert!(Place::Drive.order() < Place::Motor.order());
        assert!(Place::Drivetrain.order() < Place::Sensor.order());
    }
}
