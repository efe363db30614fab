@ A function that calls itself: the stack it needs has no bound.
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
    bl countdown
1:  b 1b

    .global countdown
    .type countdown, %function
    .thumb_func
countdown:
    push {r7, lr}
    subs r0, #1
    beq 2f
    bl countdown
2:  pop {r7, pc}
