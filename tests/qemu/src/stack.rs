//! Stack high-water mark by painting: fill the free stack below the current stack pointer with a
//! pattern, run the workload, then find the lowest word that no longer holds the pattern.
//!
//! cortex-m-rt places the stack at the top of RAM (`_stack_start`), outside every section, so
//! `llvm-size` does not count it; this measures it, so that an image's RAM figure can be given as
//! static (data + bss) plus stack.

/// Word written into the unused stack.
const PAINT: u32 = 0xC0FF_EE11;
/// Bytes left untouched just below the stack pointer when painting (the painting function's own
/// frame and any interrupt frame).
const GUARD: usize = 256;

extern "C" {
    /// Initial stack pointer (top of the stack), provided by cortex-m-rt's `link.x`.
    static _stack_start: u32;
}

/// Top of the stack (the initial stack pointer).
fn stack_top() -> usize {
    // Only the address of the linker symbol is taken; it is never read.
    core::ptr::addr_of!(_stack_start) as usize
}

/// A painted stack region, from [`paint`].
pub struct Painted {
    low: usize,
    high: usize,
}

/// Paints `bytes` bytes of stack below the current stack pointer (minus a guard).
#[inline(never)]
pub fn paint(bytes: usize) -> Painted {
    let sp = cortex_m::register::msp::read() as usize;
    let high = (sp - GUARD) & !3;
    let low = high - (bytes & !3);
    let mut a = low;
    while a < high {
        // SAFETY: the region lies below the live stack and above all statics (RAM is 4 MiB and
        // the images use far less); nothing else owns it.
        unsafe { core::ptr::write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
    Painted { low, high }
}

impl Painted {
    /// Bytes of stack used so far, from the top of the stack down to the lowest overwritten
    /// word (the whole painted region if the pattern was overwritten at its bottom).
    pub fn high_water(&self) -> usize {
        let mut a = self.low;
        // SAFETY: reads of the region painted by `paint`.
        while a < self.high && unsafe { core::ptr::read_volatile(a as *const u32) } == PAINT {
            a += 4;
        }
        stack_top() - a
    }
}
