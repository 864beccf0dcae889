//! A `#![no_std]` consumer of the codec, as a microcontroller's firmware links it (see
//! Cargo.toml): a PIR encoded into a stack buffer and decoded back, no allocator, no std.
#![no_std]

use pheromone_gateway_codec::{decode, encode, Message, PirRequest, MAX_ENCODED_BYTES};

/// Encodes a PIR for `client_id` and decodes it again: the frame's length, or 0 if the round
/// trip fails.
#[no_mangle]
pub extern "C" fn pheromone_codec_pir_roundtrip(client_id: u8, x_m: f32, y_m: f32) -> usize {
    let pir = Message::Pir(PirRequest {
        x_m,
        y_m,
        theta_rad: 0.0,
        half_wheel_base_m: 0.15,
        channel: 0,
    });
    let mut out = [0u8; MAX_ENCODED_BYTES];
    let Ok(n) = encode(&pir, client_id, &mut out) else {
        return 0;
    };
    match decode(&out[..n]) {
        Some(Ok(frame)) if frame.message == pir => n,
        _ => 0,
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}
