/* startup.c: minimal Cortex-M4F start-up for QEMU's mps2-an386 board, I/O by semihosting.
 *
 * The vector table holds the initial stack pointer and the reset handler. The reset handler
 * enables the FPU (CPACR, ARMv7-M Architecture Reference Manual B3.2.20) and jumps to newlib's
 * _start (rdimon crt0, --specs=rdimon.specs), which clears .bss, opens the semihosting
 * stdin/stdout/stderr, passes the -append command line as argv, calls main and exits.
 */
extern void _start(void);
extern void __stack_top(void); /* linker script symbol: top of the stack, not code */
void reset_handler(void);
void fault_handler(void);

void reset_handler(void)
{
  volatile unsigned long *cpacr = (volatile unsigned long *)0xE000ED88UL;
  *cpacr |= 0xFUL << 20; /* CP10 and CP11: full access */
  __asm__ volatile("dsb\n\tisb" ::: "memory");
  _start();
  for (;;) {
  }
}

void fault_handler(void)
{
  for (;;) {
  }
}

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
  __stack_top, reset_handler, fault_handler, fault_handler, fault_handler, fault_handler,
  fault_handler, 0, 0, 0, 0, fault_handler, fault_handler, 0, fault_handler, fault_handler,
};
