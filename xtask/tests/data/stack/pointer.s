@ A call through a pointer the analysis cannot resolve (an argument): it may
@ reach any function whose address the image stores, here `handlers`' two.
@ Reset 8 + dispatch 16 + (the deeper, `big`: 8 + 512) = 544.
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
    push {r7, lr}
    ldr r1, =handlers
    ldr r0, [r1, r0, lsl #2]
    bl dispatch
1:  b 1b

    .global dispatch
    .type dispatch, %function
    .thumb_func
dispatch:
    push {r4, r5, r6, lr}
    blx r0
    pop {r4, r5, r6, pc}

    .global small
    .type small, %function
    .thumb_func
small:
    push {r7, lr}
    pop {r7, pc}

    .global big
    .type big, %function
    .thumb_func
big:
    push {r7, lr}
    sub.w sp, sp, #512
    add.w sp, sp, #512
    pop {r7, pc}
    .ltorg

    .section .rodata
    .p2align 2
handlers:
    .word small
    .word big
