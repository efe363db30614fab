//! Arbitrary names and texts: checked construction rejects or accepts,
//! emission never panics and never puts 0xFF before the terminator.
#![no_main]

use hmi_proto::{Instruction, ObjName, MAX_INSTRUCTION_LEN};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: (&str, &str, i32)| {
    let (name, text, value) = data;
    let Ok(obj) = ObjName::new(name) else { return };
    let mut buf = [0u8; MAX_INSTRUCTION_LEN];
    for ins in [
        Instruction::set_text(obj, text).ok(),
        Some(Instruction::SetValue(obj, value)),
    ]
    .into_iter()
    .flatten()
    {
        let n = ins.emit(&mut buf).expect("MAX_INSTRUCTION_LEN is enough");
        assert!(n >= 3 && !buf[..n - 3].contains(&0xFF));
        assert_eq!(&buf[n - 3..n], &[0xFF; 3]);
    }
});
