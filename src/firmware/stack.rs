//! The stack's paint at boot and its high-water mark, on the chip: the raw memory access that
//! `steering_ecu::stack` (the measuring, tested on the host) cannot do. The only `unsafe` is
//! here, confined to the words of the stack region below the live stack pointer.
//!
//! flip-link links the statics at the top of RAM and `_stack_start` (the stack's top) right
//! under them; the stack grows down to the RAM start (`memory.x`), and nothing else lives in
//! between: no heap, no other section.
#![allow(unsafe_code)]

use steering_ecu::stack::{PAINT, StackUsage};

/// The stack's bottom, the RAM start (`memory.x`: `RAM : ORIGIN = 0x20000000`).
const STACK_BOTTOM: usize = 0x2000_0000;
/// Left unpainted under the stack pointer when painting, bytes: the painting loop's own frame
/// is above the pointer (ARM has no red zone), this is margin only.
const PAINT_MARGIN_BYTES: usize = 64;

unsafe extern "C" {
    /// The stack's top (cortex-m-rt's symbol, placed by flip-link under the statics).
    static _stack_start: u32;
}

fn stack_top() -> usize {
    // Only the symbol's address is taken; the word there is never read.
    (&raw const _stack_start) as usize
}

/// Paints the free stack, from the RAM start to just under the stack pointer, with [`PAINT`].
/// Called once, first thing in `main`, before any interrupt is enabled; interrupts are held off
/// anyway so that no handler's frame is painted over.
pub fn paint() {
    cortex_m::interrupt::free(|_| {
        let sp = cortex_m::register::msp::read() as usize;
        let end = sp.saturating_sub(PAINT_MARGIN_BYTES).min(stack_top());
        let mut addr = STACK_BOTTOM;
        while addr + 4 <= end {
            // SAFETY: `addr` is word-aligned, inside RAM (STACK_BOTTOM up to under the stack
            // pointer), and below the live stack: no frame, static or handler (interrupts are
            // off) uses it, so writing it cannot change anything that is read later except
            // through this module.
            unsafe { core::ptr::write_volatile(addr as *mut u32, PAINT) };
            addr += 4;
        }
    });
}

/// The high-water mark since [`paint`]: the stack region's words read from the bottom up to
/// the first that lost its paint (about the free stack's size in reads: 0.2 ms at 180 MHz for
/// 120 KiB; interrupts stay on). A handler may push its frame meanwhile; a word read then is
/// either still paint or already its data, and either reading is a true depth.
pub fn usage() -> StackUsage {
    let words = stack_top().saturating_sub(STACK_BOTTOM) / 4;
    StackUsage::measure(words, |i| {
        // SAFETY: `i < words`, so the address is a word-aligned word of the stack region in
        // RAM; a volatile read of it has no side effect, whoever owns the word.
        unsafe { core::ptr::read_volatile((STACK_BOTTOM + 4 * i) as *const u32) }
    })
}
