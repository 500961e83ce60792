//! Support shared by the QEMU firmware images (`selftest`, `bench`, `sizeprobe`).
//!
//! Runs on `qemu-system-arm -machine mps2-an386 -cpu cortex-m4` (Cortex-M4F, FPU enabled by
//! cortex-m-rt's reset handler for the `thumbv7em-none-eabihf` target).
//!
//! * Logging: `defmt` frames over semihosting stdout (global logger from `defmt-semihosting`),
//!   decoded on the host by `ferrosid-tests`. Nothing else may write to stdout.
//! * Exit: semihosting `SYS_EXIT_EXTENDED`, so QEMU's exit status is the firmware's exit code.
//! * Panics: [`report_panic`] writes `panicked at FILE:LINE` to semihosting **stderr** (never into
//!   the defmt stream on stdout) and exits with code [`EXIT_PANIC`].
//! * Instruction counting: [`InstructionCounter`] (SysTick deltas, deterministic under
//!   `qemu -icount shift=0`).
#![no_std]

// Critical-section implementation (single core) used by defmt-semihosting.
use cortex_m as _;
// Global defmt logger writing frames to semihosting stdout.
use defmt_semihosting as _;

pub mod icount;
pub mod reference;
pub mod stack;

pub use icount::InstructionCounter;

/// Exit code of an image whose checks all passed.
pub const EXIT_SUCCESS: i32 = 0;
/// Exit code of an image in which at least one check failed.
pub const EXIT_FAILURE: i32 = 1;
/// Exit code after a panic (mirrors Rust's test harness convention).
pub const EXIT_PANIC: i32 = 101;

/// Ends the emulation with `code` as QEMU's exit status.
pub fn exit(code: i32) -> ! {
    semihosting::process::exit(code)
}

/// `true` when the semihosting command line (QEMU `-semihosting-config arg=...`) contains
/// exactly the word `flag`. Returns `false` when no command line is available.
pub fn has_arg(flag: &str) -> bool {
    match semihosting::experimental::env::args::<256>() {
        Ok(args) => (&args).any(|a| a == Ok(flag)),
        Err(_) => false,
    }
}

/// Writes `bytes` to semihosting stderr; errors are ignored (there is nowhere to report them).
fn write_stderr(bytes: &[u8]) {
    use semihosting::io::Write as _;
    if let Ok(mut err) = semihosting::io::stderr() {
        let _ = err.write_all(bytes);
    }
}

/// Formats `value` in decimal into `buf` and returns the digits (no allocation, no core::fmt).
fn decimal(mut value: u32, buf: &mut [u8; 10]) -> &[u8] {
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (value % 10) as u8;
        value /= 10;
        if value == 0 || i == 0 {
            break;
        }
    }
    &buf[i..]
}

/// Panic handler body of the test images: writes `panicked at FILE:LINE` to semihosting stderr
/// (never into the defmt stream on stdout) and exits with [`EXIT_PANIC`]. Each image binds it
/// with `#[panic_handler]` (the size probe uses a bare exit instead, as a product would).
pub fn report_panic(info: &core::panic::PanicInfo) -> ! {
    write_stderr(b"panicked at ");
    match info.location() {
        Some(loc) => {
            let mut buf = [0u8; 10];
            write_stderr(loc.file().as_bytes());
            write_stderr(b":");
            write_stderr(decimal(loc.line(), &mut buf));
        }
        None => write_stderr(b"<unknown location>"),
    }
    write_stderr(b"\n");
    exit(EXIT_PANIC)
}
