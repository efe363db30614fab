@ A frame whose size comes from an argument: the analysis cannot bound it.
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
    bl scratch
1:  b 1b

    .global scratch
    .type scratch, %function
    .thumb_func
scratch:
    push {r7, lr}
    mov r7, sp
    sub sp, r0
    mov sp, r7
    pop {r7, pc}
