//! Bits of the general-purpose and advanced timers' registers the drivers write (RM0008 §14.4, §15.4).

// Timer register bits (RM0008 §14.4 for TIM1, §15.4 for TIM2–TIM4; the
// bits used here sit at the same places in both).
/// TIMx_CR1 CEN (bit 0): counter enable.
pub(super) const CR1_CEN: u32 = 1;
/// TIMx_CR1 UDIS (bit 1): update events disabled, the shadow registers
/// (PSC, ARR, CCRx) keep their values (§15.4.1).
pub(super) const CR1_UDIS: u32 = 1 << 1;
/// TIMx_CR1 ARPE (bit 7): ARR preloaded.
pub(super) const CR1_ARPE: u32 = 1 << 7;
/// TIMx_EGR UG (bit 0): update generation (shadows loaded, counter 0).
pub(super) const EGR_UG: u32 = 1;
/// TIMx_CCMR1 (output) OC1PE (bit 3): CCR1 preloaded.
pub(super) const CCMR1_OC1PE: u32 = 1 << 3;
/// TIMx_CCMR1 OC1M (bits 6:4) = 110: PWM mode 1 (OC1REF high while CNT < CCR1).
pub(super) const CCMR1_OC1M_PWM1: u32 = 0b110 << 4;
/// TIMx_CCMR1 OC1M = 100: force inactive level, OC1REF low at once
/// (§15.4.7: the mode bits are not preloaded).
pub(super) const CCMR1_OC1M_FORCE_INACTIVE: u32 = 0b100 << 4;
/// TIMx_CCMR1 OC1M field mask.
pub(super) const CCMR1_OC1M_MASK: u32 = 0b111 << 4;
/// TIMx_CCER CC1E (bit 0): OC1 output enabled, CC1P = 0 (active high).
pub(super) const CCER_CC1E: u32 = 1;
/// TIM1_BDTR OSSR (bit 11) and OSSI (bit 10): with MOE = 0 the output stays
/// enabled at its idle level OIS1 (TIM1_CR2 bit 8, left 0: low) instead of
/// being released (RM0008 §14.4.18 and Table 83). MOE is cleared by the
/// debug halt (DBG_TIM1_STOP) and by [`safe_state`].
pub(super) const BDTR_OSSR_OSSI: u32 = (1 << 11) | (1 << 10);
/// TIMx_SR UIF (bit 0), CC1IF (bit 1), CC1OF (bit 9) (§15.4.5).
pub(super) const SR_UIF: u32 = 1;
pub(super) const SR_CC1IF: u32 = 1 << 1;
pub(super) const SR_CC1OF: u32 = 1 << 9;
