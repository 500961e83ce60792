//! Robust control with receipts: the numerical core that turns an identified plant into a
//! controller an engineer can trust, and the evidence (receipts) that it can be trusted.
//!
//! Typical chain (each step serde-serialisable for `receipts.json` and the report):
//!
//! 1. [`audit::audit_nonlinearity`] — overlay FRFs measured at several excitation amplitudes
//!    ([`audit::FrfRun::from_etfe`]) and flag bands near crossover where gain/phase shift or
//!    coherence drops: [`audit::NonlinearityAudit`] with a [`audit::Verdict`].
//! 2. [`uncertainty::multiplicative_envelope`] + [`uncertainty::fit_uncertainty_weight`] — the
//!    envelope l_m(ω) of a family of responses around G0 and a stable minimum-phase W_m(s)
//!    that overbounds it ([`uncertainty::UncertaintyWeight`]: `num`/`den` in s, rad/s).
//! 3. [`pid::tune_pid`] — PID (+ derivative filter, optional roll-off) maximising crossover
//!    subject to M_s, ‖W_m T‖∞ < 1 and ‖KS‖∞ ([`pid::TunedPid`], with the firmware form
//!    [`pid::DiscretePid`], Tustin prewarped at crossover).
//! 4. [`receipts::compute_receipts`] — every claim re-verified independently as
//!    [`receipts::Receipt`]s (margins, M_s, M_t, ‖W_m T‖∞, disturbance bandwidth, peak KS
//!    against the actuator limit, saturated step, ETFE phase agreement, cross-validation fit).
//!
//! Building blocks: [`norms`] (H∞ norm by Hamiltonian bisection, continuous and discrete),
//! [`loops`] (S, T, KS, GS of a SISO loop; gain/phase margins), [`discretize`] (Tustin with
//! prewarping), [`step`] (closed-loop step through a hard actuator saturation).
//!
//! Units: frequencies in Hz (`_hz`) or rad/s (`_rad_s`, and all `w`), time in seconds.
pub mod audit;
pub mod discretize;
pub mod loops;
pub mod norms;
pub mod pid;
pub mod receipts;
pub mod step;
pub mod uncertainty;
