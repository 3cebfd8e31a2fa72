#define_import_path displace::batch
#import displace::convention::{FLAG_CELL_CAP, FLAG_LOOP_CUT, RayIn}
#import displace::surface::{cell_cap_reached, loop_cut}

// What both batch queries (trace_compute.wgsl, technique_compute.wgsl)
// share, as batch.rs does on the Rust side: the rays of group 1 and the
// guard bits every result carries.

@group(1) @binding(0) var<storage, read> rays: array<RayIn>;

// A result's flags: `found_flag` when `found`, and FLAG_CELL_CAP and
// FLAG_LOOP_CUT when the walk this invocation ran hit its cell cap or had
// its loops cut short by the driver (batch.rs `check_cell_cap`).
fn result_flags(found: bool, found_flag: u32) -> u32 {
    var flags = 0u;
    if (found) {
        flags |= found_flag;
    }
    if (cell_cap_reached) {
        flags |= FLAG_CELL_CAP;
    }
    if (loop_cut) {
        flags |= FLAG_LOOP_CUT;
    }
    return flags;
}
