//! Size probe: the smallest realistic power-up identification image, measured with `llvm-size`.
//!
//! PRBS excitation (10-bit MLS) drives a plant (a first-order lag simulated here in `f32`, as
//! the actuator would be), both signals stream into `Welch<1024>` (Hann, 50 % overlap), then
//! the coherence gate and H1 are evaluated and a summary is logged with defmt. The Welch state
//! is a static in `.bss` (`cortex_m::singleton!`), so it counts as static RAM; the stack
//! (cortex-m-rt puts it at the top of RAM, outside any section) does not, so its high-water
//! mark is measured by painting and logged as `STACK <bytes> bytes`.
//!
//! Exit code 0 when the estimate is sane: at least half of the bins pass the 0.9 coherence gate
//! and |H1| at bin N/4 is within 2 % of the plant's exact gain there.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use ferrosid_firmware::excitation::Prbs;
use ferrosid_firmware::{Excitation, Welch};
use ferrosid_qemu::{exit, EXIT_FAILURE, EXIT_SUCCESS};

/// Sample rate (Hz).
const FS: f32 = 1000.0;
/// Segment length of the size figure in the issue.
const N: usize = 1024;

/// Minimal panic handler, as a product image would have: exit with the panic code, no text
/// (the test images print the panic location instead; that diagnostic is not product code).
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    exit(ferrosid_qemu::EXIT_PANIC)
}

#[entry]
fn main() -> ! {
    let painted = ferrosid_qemu::stack::paint(32 * 1024);
    let Some(slot) = cortex_m::singleton!(: Option<Welch<N>> = None) else {
        exit(EXIT_FAILURE)
    };
    *slot = Welch::new(Welch::<N>::default_config(FS)).ok();
    let (Some(welch), Ok(mut prbs)) = (slot.as_mut(), Prbs::new(10, 1, 1.0, 1)) else {
        exit(EXIT_FAILURE)
    };
    let mut y = 0.0f32;
    for _ in 0..N + 15 * N / 2 {
        let u = prbs.next_sample();
        y = 0.98 * y + 0.02 * u;
        welch.push(u, y);
    }
    let gate = welch.gate(0.9);
    // At bin N/4 (ω = π/2, cos ω = 0) the lag's gain is exactly 0.02/√(1 + 0.98²).
    let (re, im) = welch.h1(N / 4).unwrap_or((0.0, 0.0));
    let h1_mag = libm::sqrtf(re * re + im * im);
    let h_true = 0.02 / libm::sqrtf(1.0 + 0.98 * 0.98);
    defmt::println!(
        "sizeprobe: {=u32} averages, {=usize}/{=usize} bins pass coherence 0.9, |H1(N/4)| = {=f32} (true {=f32})",
        welch.averages(),
        gate.count(),
        welch.bins(),
        h1_mag,
        h_true
    );
    defmt::println!("STACK {=usize} bytes", painted.high_water());
    let ok = gate.count() * 2 >= welch.bins() && (h1_mag / h_true - 1.0).abs() < 0.02;
    exit(if ok { EXIT_SUCCESS } else { EXIT_FAILURE })
}
