/*
 * Cortex-M4F start-up for the firmware image (QEMU mps2-an386, or any M4F part with the
 * memory map of mcu.ld). Written in assembly so that no floating-point instruction can run
 * before the FPU is enabled: the C/C++ code is built with -mfloat-abi=hard and the compiler is
 * free to use VFP registers anywhere (even for memcpy-like moves), which would fault (NOCP
 * UsageFault) with CPACR still at its reset value.
 */
  .syntax unified
  .cpu cortex-m4
  .fpu fpv4-sp-d16
  .thumb

  .section .isr_vector, "a", %progbits
  .align 2
  .global __isr_vector
__isr_vector:
  .word __stack_top           /* initial main stack pointer */
  .word Reset_Handler
  .word Fault_Handler         /* NMI */
  .word Fault_Handler         /* HardFault */
  .word Fault_Handler         /* MemManage */
  .word Fault_Handler         /* BusFault */
  .word Fault_Handler         /* UsageFault */
  .word 0, 0, 0, 0            /* reserved */
  .word Fault_Handler         /* SVCall */
  .word Fault_Handler         /* DebugMonitor */
  .word 0                     /* reserved */
  .word Fault_Handler         /* PendSV */
  .word SysTick_Handler       /* SysTick: the firmware polls it, the handler only counts wraps */

  .section .text.Reset_Handler, "ax", %progbits
  .align 2
  .global Reset_Handler
  .type Reset_Handler, %function
  .thumb_func
Reset_Handler:
  /* 1. FPU: full access for CP10 and CP11 (CPACR bits 20-23), then barriers so the next
   *    instruction sees it (ARMv7-M ARM B3.2.20). */
  ldr   r0, =0xE000ED88
  ldr   r1, [r0]
  orr   r1, r1, #(0xF << 20)
  str   r1, [r0]
  dsb
  isb
  /* 2. .data: copy its load image from flash to RAM (word aligned by the linker script). */
  ldr   r0, =__data_load
  ldr   r1, =__data_start
  ldr   r2, =__data_end
1:
  cmp   r1, r2
  bhs   2f
  ldr   r3, [r0], #4
  str   r3, [r1], #4
  b     1b
2:
  /* 3. .bss: zero. */
  ldr   r1, =__bss_start
  ldr   r2, =__bss_end
  movs  r3, #0
3:
  cmp   r1, r2
  bhs   4f
  str   r3, [r1], #4
  b     3b
4:
  /* 4. Paint the whole stack reservation (nothing is on it yet) so that the firmware can
   *    report its high-water mark at exit. */
  ldr   r1, =__stack_limit
  ldr   r2, =__stack_top
  ldr   r3, =0x5AA5F00D
5:
  cmp   r1, r2
  bhs   6f
  str   r3, [r1], #4
  b     5b
6:
  /* 5. No C++ static constructors are allowed (the link script asserts .init_array is empty),
   *    so there is nothing else to run before main. */
  bl    main
  bl    platform_exit
7:
  b     7b
  .size Reset_Handler, . - Reset_Handler

  .section .text.Fault_Handler, "ax", %progbits
  .align 2
  .global Fault_Handler
  .weak Fault_Handler
  .type Fault_Handler, %function
  .thumb_func
Fault_Handler:
  mrs   r0, ipsr
  b     platform_fault
  .size Fault_Handler, . - Fault_Handler

  .section .text.SysTick_Handler, "ax", %progbits
  .align 2
  .weak SysTick_Handler
  .type SysTick_Handler, %function
  .thumb_func
SysTick_Handler:
  bx    lr
  .size SysTick_Handler, . - SysTick_Handler
