//! Deterministic instruction counting under `qemu-system-arm -icount shift=0`.
//!
//! DWT CYCCNT reads 0 under QEMU. With `-icount shift=N` QEMU's virtual clock advances by 2^N ns
//! per executed instruction, and the SysTick timer (clocked from the core clock, 25 MHz on
//! mps2-an386) derives its count from that virtual clock. SysTick deltas are therefore exact,
//! deterministic instruction counts divided by a constant number of instructions per tick
//! (40 at shift=0 and 25 MHz). That factor is not assumed: [`InstructionCounter::calibrate`]
//! measures it on a loop whose instruction count is known exactly.
//!
//! SysTick is a 24-bit down-counter: a single delta is correct only while fewer than 2^24 ticks
//! (about 671 M instructions at 40 instructions per tick) elapse. [`InstructionCounter::lap`]
//! accumulates deltas into a 64-bit total; call it at least once per such interval (the bench
//! calls it once per block of samples).

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;

/// Mask of the 24-bit SysTick counter.
const MASK: u32 = 0x00FF_FFFF;

/// Free-running SysTick used as an instruction counter.
pub struct InstructionCounter {
    syst: SYST,
    last: u32,
    ticks: u64,
}

impl InstructionCounter {
    /// Takes SysTick, sets it free-running from the core clock with the full 24-bit reload.
    pub fn new(mut syst: SYST) -> Self {
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(MASK);
        syst.clear_current();
        syst.enable_counter();
        let last = SYST::get_current();
        InstructionCounter {
            syst,
            last,
            ticks: 0,
        }
    }

    /// Adds the ticks elapsed since the previous `lap` (or `reset`) to the running total and
    /// returns the total in SysTick ticks.
    #[inline(always)]
    pub fn lap(&mut self) -> u64 {
        let now = SYST::get_current();
        // Down-counter: elapsed = last - now (mod 2^24).
        self.ticks += u64::from(self.last.wrapping_sub(now) & MASK);
        self.last = now;
        self.ticks
    }

    /// Zeroes the running total.
    #[inline(always)]
    pub fn reset(&mut self) {
        self.last = SYST::get_current();
        self.ticks = 0;
    }

    /// Ticks elapsed while running `f`, from two raw counter reads (no running total; `f` must
    /// take fewer than 2^24 ticks). The reads themselves add a small constant: measure an empty
    /// closure the same way and subtract it.
    #[inline(always)]
    pub fn ticks_of(&mut self, f: impl FnOnce()) -> u32 {
        let start = SYST::get_current();
        f();
        let end = SYST::get_current();
        self.last = end;
        start.wrapping_sub(end) & MASK
    }

    /// Measures the number of executed instructions per SysTick tick on a loop of exactly
    /// `2 * (iterations + 1)` instructions (`cortex_m::asm::delay`: `subs`, `bne` per iteration).
    /// Returns `(instructions, ticks)` of that loop, so the caller can form the ratio.
    pub fn calibrate(&mut self, iterations: u32) -> (u64, u64) {
        self.reset();
        cortex_m::asm::delay(iterations);
        let ticks = self.lap();
        (2 * (u64::from(iterations) + 1), ticks)
    }

    /// Gives SysTick back.
    pub fn free(self) -> SYST {
        self.syst
    }
}
