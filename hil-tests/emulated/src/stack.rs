//! Stack use, measured by painting: the free stack below the caller is filled with a pattern,
//! the code runs, and the lowest word that lost the pattern is as deep as the stack went,
//! exception frames of interrupts taken meanwhile included. The stack is the linker's
//! `_stack_end.._stack_start`: with flip-link (../.cargo/config.toml) the RAM from its start
//! up to the statics, which sit at the top.

/// The pattern; cortex-m-rt's `paint-stack` feature and probe-rs use the same one.
const PAINT: u32 = 0xCCCC_CCCC;

#[allow(unsafe_code)]
unsafe extern "C" {
    // Linker symbols (cortex-m-rt's link.x, redefined by flip-link): only their addresses are
    // used.
    static _stack_start: u32;
    static _stack_end: u32;
}

/// The stack's (lowest address, top).
pub fn bounds() -> (usize, usize) {
    (
        core::ptr::addr_of!(_stack_end) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
}

/// The stack pointer now.
pub fn pointer() -> usize {
    cortex_m::register::msp::read() as usize
}

/// Runs `f`; returns its result and the bytes of stack it used below this call's stack
/// pointer. Not inlined, so that the painted range ends at a known frame.
#[inline(never)]
pub fn depth_of<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let (bottom, _) = bounds();
    let sp = pointer();
    let words = sp.saturating_sub(bottom) / 4;
    let base = bottom as *mut u32;
    for i in 0..words {
        // SAFETY: `bottom + 4 i` is below the stack pointer and at or above the stack's lowest
        // address: free stack, which no frame occupies (the AAPCS has no red zone) and no
        // interrupt is using (none is pending while this loop runs).
        #[allow(unsafe_code)]
        unsafe {
            base.add(i).write_volatile(PAINT)
        };
    }
    let out = core::hint::black_box(f());
    let untouched = (0..words)
        .take_while(|&i| {
            // SAFETY: the same words as above, read back.
            #[allow(unsafe_code)]
            let word = unsafe { base.add(i).read_volatile() };
            word == PAINT
        })
        .count();
    (out, (words - untouched) * 4)
}
