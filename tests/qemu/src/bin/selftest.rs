//! On-target self-test (placeholder payload while the firmware algorithms land).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use ferrosid_qemu::{exit, EXIT_FAILURE, EXIT_SUCCESS};

#[entry]
fn main() -> ! {
    let inject = ferrosid_qemu::has_arg("--inject-failure");
    let p = cortex_m::Peripherals::take();
    let mut ok = match p {
        Some(p) => p.SCB.cpacr.read() & (0xF << 20) == (0xF << 20),
        None => false,
    };
    if inject { ok = !ok; }
    defmt::println!("CHECK fpu_enabled {=str}", if ok { "PASS" } else { "FAIL" });
    if ferrosid_qemu::has_arg("--panic") {
        panic!("requested by --panic");
    }
    defmt::println!("SELFTEST {=str} {=u32}/1", if ok { "PASS" } else { "FAIL" }, if ok {1} else {1});
    exit(if ok { EXIT_SUCCESS } else { EXIT_FAILURE })
}
