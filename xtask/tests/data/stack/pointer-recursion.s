@ A call through a pointer that may reach a function calling back through
@ the same pointer: recursion the analysis cannot bound.
    .syntax unified
    .thumb
    .section .vector_table, "a"
    .word _stack_start
    .word Reset

    .text
    .global Reset
    .type Reset, %function
    .thumb_func
Reset:
    ldr r0, =callbacks
    ldr r0, [r0]
    bl run
1:  b 1b

    .global run
    .type run, %function
    .thumb_func
run:
    push {r4, lr}
    sub sp, #24
    blx r0
    add sp, #24
    pop {r4, pc}

    .global again
    .type again, %function
    .thumb_func
again:
    push {r7, lr}
    ldr r0, =callbacks
    ldr r0, [r0]
    bl run
    pop {r7, pc}
    .ltorg

    .data
    .p2align 2
callbacks:
    .word again
