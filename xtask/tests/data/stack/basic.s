@ Every kind of entry and frame the analysis reads. Expected depths (bytes):
@ Reset 104 (init masked: 64 + leaf 40), preemptible 16 (idle);
@ Irq0 (priority 0xe0) 176 (a jump table's case: 8 + 128 + leaf 40);
@ Irq1 (0xc0) 1216 (208 + deep 1008, masked), preemptible 208;
@ SysTick (0x80) 8; HardFault and NMI 72 on a fresh stack.
@ Worst case: 16 + (36 + 176) + (36 + 1216) + 36 + 36 = 1552.
    .syntax unified
    .thumb

    .section .vector_table, "a"
    .word _stack_start
    .word Reset
    .word NMI
    .word HardFault
    .word 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
    .word SysTick
    .word Irq0
    .word Irq1

    .text
    .macro function name
    .global \name
    .type \name, %function
    .thumb_func
\name:
    .endm

    function Reset
    ldr r0, =0xE000E400     @ NVIC_IPR
    movs r1, #0xe0
    strb r1, [r0, #0]       @ IRQ0
    movs r1, #0xc0
    strb r1, [r0, #1]       @ IRQ1
    ldr r0, =0xE000ED23     @ SHPR3, SysTick
    movs r1, #0x80
    strb r1, [r0]
    cpsid i
    bl init
    cpsie i
    b idle

    function init
    push {r4, r5, r6, r7, lr}
    sub sp, #44
    bl leaf
    add sp, #44
    pop {r4, r5, r6, r7, pc}

    function idle
    push {r7, lr}
    sub sp, #8
1:  wfi
    b 1b

    function leaf
    push {r7, lr}
    sub.w sp, sp, #32
    add sp, #32
    pop {r7, pc}

    function Irq0
    push {r4, lr}
    cmp r0, #2
    bhi 4f
    tbb [pc, r0]
5:  .byte (1f - 5b) / 2
    .byte (2f - 5b) / 2
    .byte (3f - 5b) / 2
    .p2align 1
1:  sub sp, #16
    add sp, #16
    pop {r4, pc}
2:  sub sp, #128
    bl leaf
    add sp, #128
    pop {r4, pc}
3:  pop {r4, pc}
4:  pop {r4, pc}

    function Irq1
    push {r7, lr}
    ldr r3, =leaf
    blx r3
    cmp r0, #0
    itt eq
    popeq {r7, lr}
    beq.w leaf
    sub sp, #200
    cpsid i
    bl deep
    cpsie i
    add sp, #200
    pop {r7, pc}

    function deep
    push {r7, lr}
    sub.w sp, sp, #1000
    add.w sp, sp, #1000
    pop {r7, pc}

    function SysTick
    push {r7, lr}
    pop {r7, pc}

    function HardFault
    ldr r0, =_stack_start
    msr msp, r0
    b fatal

    function NMI
    b HardFault

    function fatal
    push {r7, lr}
    sub sp, #64
1:  b 1b
    .ltorg
