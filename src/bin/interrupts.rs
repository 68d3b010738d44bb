//! The device part of the vector table: the 32 external interrupts of the MPS2 AN386 (the
//! CMSDK peripherals' lines; QEMU's `mps2-an386` models the same 32). Shared by every image
//! (`mod interrupts;` in each).
//!
//! cortex-m-rt's `device` feature takes this table from the application instead of its
//! generic 240-entry one, which would cost 832 bytes of flash for interrupts this board does
//! not have. None is used: every entry is cortex-m-rt's `DefaultHandler`. A board with more
//! interrupt lines (an STM32F4 has 82) needs a longer table here.

unsafe extern "C" {
    /// cortex-m-rt's handler for every exception and interrupt without its own.
    fn DefaultHandler();
}

/// External interrupts of the AN386.
const IRQS: usize = 32;

/// The device-specific part of the vector table, placed after the exceptions by
/// cortex-m-rt's linker script.
#[unsafe(link_section = ".vector_table.interrupts")]
#[unsafe(no_mangle)]
#[used]
static __INTERRUPTS: [unsafe extern "C" fn(); IRQS] = [DefaultHandler; IRQS];
