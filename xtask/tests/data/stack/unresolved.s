@ A call through a pointer (an argument) in an image that stores no
@ function's address: nothing it could reach is known.
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
    bl dispatch
1:  b 1b

    .global dispatch
    .type dispatch, %function
    .thumb_func
dispatch:
    push {r7, lr}
    blx r0
    pop {r7, pc}
