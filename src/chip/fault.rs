//! The HardFault entry the firmware uses, as a macro so that the firmware and the emulated
//! suite (which overflows the stack on purpose to test it) define the same one. The library
//! itself stays free of unsafe code: the macro expands in the crate that invokes it.
//!
//! Why not cortex-m-rt's `#[exception] fn HardFault`: with flip-link the stack grows down to
//! the RAM start, so a stack overflow faults with the stack pointer just below RAM. The
//! exception's own stacking fails there, and the first push of a Rust handler's prologue
//! faults again inside the HardFault handler: the core locks up and the handler's body (the
//! drive off) never runs. Measured under QEMU with the emulated suite's `stack-overflow`
//! feature: "Lockup: can't escalate 3 to HardFault". This entry touches no stack: it moves the
//! main stack pointer back to the top of the stack (`_stack_start`; the handler never returns,
//! so what was there is not needed) and only then branches to the handler's body.

/// Defines `HardFault` (the vector cortex-m-rt's table points at) as a stack-free entry that
/// resets the main stack pointer to `_stack_start` and branches to `$body`, an
/// `extern "C" fn() -> !`. Invoke once, at the crate root of a `thumbv7em-none-eabihf` binary
/// that links cortex-m-rt; the invoking crate must allow `unsafe_code` for it.
#[macro_export]
macro_rules! hard_fault_entry {
    ($body:path) => {
        // SAFETY: the vector is entered by the core in handler mode; the three instructions use
        // no stack, and `$body` never returns, so discarding the old stack is sound.
        #[unsafe(naked)]
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn HardFault() -> ! {
            core::arch::naked_asm!(
                "movw r0, :lower16:_stack_start",
                "movt r0, :upper16:_stack_start",
                "msr msp, r0",
                "b {body}",
                body = sym $body,
            )
        }
    };
}
