//! `cargo xtask bench`: instructions per sample and stack depth in QEMU, flash and static RAM
//! of the images against their budgets, host samples per second, the diagnosis's speed.

use std::time::Instant;

use crate::process::{output, show};
use crate::task::{Result, Xtask};

/// Flash budget of the flight image \[B\]: 32 KiB.
pub(crate) const FLASH_BUDGET: u64 = 32 * 1024;

/// Static RAM budget of the flight image \[B\]: 8 KiB.
pub(crate) const RAM_BUDGET: u64 = 8 * 1024;

/// Flash (what is loaded: vector table, code, constants, initial values of `.data`) and
/// static RAM (`.data`, `.bss`, `.uninit`) of an image, from `llvm-size -A`.
pub(crate) fn flash_and_ram(sections: &str) -> Result<(u64, u64)> {
    let (mut flash, mut ram, mut seen) = (0, 0, 0);
    for line in sections.lines() {
        let mut cols = line.split_whitespace();
        let (Some(name), Some(size)) = (cols.next(), cols.next()) else { continue };
        let Ok(size) = size.parse::<u64>() else { continue };
        match name {
            ".vector_table" | ".text" | ".rodata" => flash += size,
            ".data" => (flash, ram) = (flash + size, ram + size),
            ".bss" | ".uninit" => ram += size,
            _ => continue,
        }
        seen += 1;
    }
    if seen < 4 {
        return Err(format!(
            "llvm-size -A: expected .vector_table, .text, .rodata, .data and .bss, found {seen} of them"
        ));
    }
    Ok((flash, ram))
}

impl Xtask {
    /// `cargo xtask bench`: instructions per sample of each method/model case, the worst
    /// single step and the step's stack high-water mark (the `bench` firmware in QEMU,
    /// `-icount shift=0`), flash and static RAM of the replay firmware, the link-check image
    /// and the flight image (`llvm-size`), the host's samples per second (criterion), and the
    /// diagnosis's wall time on 30 000- and 260 000-row pairs against its budgets.
    pub(crate) fn bench(&mut self) -> bool {
        let started = Instant::now();
        let ok = self.step(1, "toolchain", Xtask::setup_toolchain)
            && self.step(2, "build", |x| {
                x.build_firmware()?;
                let args = ["--release", "--features", "firmware-log", "--bin", "bench"];
                x.run(x.thumb_cargo("build", args)?)
            })
            && self.step(3, "instructions per sample (QEMU)", |x| x.run_qemu_in(&x.elf("bench"), &x.root))
            && self.step(4, "size of the replay firmware, the link-check image and the flight image", |x| {
                x.build_linkcheck()?;
                let mut c = x.command("llvm-size");
                c.arg(x.elf("replay")).arg(x.elf("linkcheck")).arg(x.elf("flight"));
                x.run(c)?;
                let mut c = x.command("llvm-size");
                c.arg("-A").arg(x.elf("flight"));
                println!("$ {}", show(&c));
                let sections = output(&mut c)?;
                print!("{sections}");
                let (flash, ram) = flash_and_ram(&sections)?;
                let verdict = |used: u64, budget: u64| if used <= budget { "met" } else { "MISSED" };
                println!("flight image: flash {flash} B of {FLASH_BUDGET} ({})", verdict(flash, FLASH_BUDGET));
                println!("flight image: static RAM {ram} B of {RAM_BUDGET} ({})", verdict(ram, RAM_BUDGET));
                if flash > FLASH_BUDGET || ram > RAM_BUDGET {
                    return Err("the flight image is over its flash or RAM budget".into());
                }
                Ok(())
            })
            && self.step(5, "host samples per second (criterion)", |x| {
                x.run(x.host_cargo(["bench", "-p", "host-tests", "--bench", "throughput"]))
            })
            && self.step(6, "bins-cal diagnose: 30 000 rows < 2 s, 260 000 rows < 10 s (release, one thread)", |x| {
                x.run(x.host_cargo(["run", "--release", "-q", "-p", "bins-cal", "--example", "diagnose_speed"]))
            });
        self.summary(started);
        ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `llvm-size -A` of a flight image as the Debian LLVM prints it (sizes changed).
    const SIZES: &str = "flight  :
section               size        addr
.vector_table          192           0
.text                31912         192
.rodata                456       32104
.data                   16   536870912
.gnu.sgstubs             0       32576
.bss                  2892   536870928
.uninit                  4   536873820
.defmt                   1           0
.debug_loc          443013           0
Total              1621862
";

    #[test]
    fn flash_counts_what_is_loaded_and_ram_what_is_reserved() {
        assert_eq!(flash_and_ram(SIZES), Ok((192 + 31_912 + 456 + 16, 16 + 2_892 + 4)));
    }

    #[test]
    fn a_listing_without_the_image_sections_is_an_error() {
        let err = flash_and_ram("section size addr\n.debug_loc 10 0\nTotal 10\n").unwrap_err();
        assert!(err.contains("found 0"), "{err}");
    }
}
