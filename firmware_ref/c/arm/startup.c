/* Minimal Cortex-M startup for running the hdrg C twin on QEMU's MPS2 boards (mps2-an386:
 * Cortex-M4, mps2-an500: Cortex-M7) with newlib + librdimon semihosting: stdin, stdout,
 * stderr and exit() go to the host through semihosting (qemu -semihosting).
 *
 * The vector table holds the initial stack pointer and the reset handler; every other
 * exception stops the program with exit status 3 (semihosting SYS_EXIT), so that a fault
 * never hangs a test.  Reset: copy .data, zero .bss, open the semihosting handles, run main,
 * exit with its status.  Memory map: link.ld. */
#include <stdint.h>
#include <stdlib.h>

extern uint32_t __data_load__[], __data_start__[], __data_end__[], __bss_start__[], __bss_end__[];
extern uint32_t __stack_top__[];
extern int main(void);
extern void initialise_monitor_handles(void);
void reset_handler(void);
void fault_handler(void);

__attribute__((section(".vectors"), used))
const void *const hdrg_vectors[16] = {
    __stack_top__, (const void *)reset_handler, (const void *)fault_handler, (const void *)fault_handler,
    (const void *)fault_handler, (const void *)fault_handler, (const void *)fault_handler, 0, 0, 0, 0,
    (const void *)fault_handler, (const void *)fault_handler, 0, (const void *)fault_handler,
    (const void *)fault_handler,
};

/* -nostartfiles drops crti/crtn: newlib's __libc_init_array/__libc_fini_array call these. */
void _init(void);
void _fini(void);
void _init(void)
{
}

void _fini(void)
{
}

void fault_handler(void)
{
    _Exit(3);
}

void reset_handler(void)
{
    uint32_t *s = __data_load__, *d = __data_start__;
    while (d < __data_end__) {
        *d++ = *s++;
    }
    for (d = __bss_start__; d < __bss_end__;) {
        *d++ = 0;
    }
    initialise_monitor_handles();
    exit(main());
}
