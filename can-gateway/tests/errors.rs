//! Every error of can-gateway is a `core::error::Error` whose message says what went
//! wrong in words (the first sentence of the variant's documentation, and its data).

use can_gateway::codec::Field;
use can_gateway::secoc::AuthError;
use can_gateway::{DecodeError, EncodeError};
use core::error::Error;

/// `e`'s message contains `words`.
fn says(e: &dyn Error, words: &str) {
    let text = e.to_string();
    assert!(text.contains(words), "{text:?} should say {words:?}");
}

#[test]
fn every_error_says_what_went_wrong() {
    says(&DecodeError::Crc, "CRC does not match");
    says(&DecodeError::Stale, "not newer");
    says(&DecodeError::OutOfRange(Field::Lane), "Lane");
    says(&AuthError::UnknownKey, "no key");
    says(&AuthError::BadMac, "MAC does not match");
    says(&EncodeError::Frame, "frame type refused");
    says(
        &EncodeError::OutOfRange(Field::TrackHeading),
        "TrackHeading",
    );
}

#[test]
fn a_refused_authenticator_is_the_decode_errors_source() {
    let e = DecodeError::Auth(AuthError::BadMac);
    says(&e, "authenticator was refused: the MAC does not match");
    let source = e.source().expect("the authenticator's error");
    assert_eq!(source.to_string(), AuthError::BadMac.to_string());
    assert!(DecodeError::Crc.source().is_none());
}

#[test]
fn an_error_goes_into_an_applications_own() {
    fn decode() -> Result<(), Box<dyn Error>> {
        Err(DecodeError::Crc)?
    }
    assert_eq!(
        decode().expect_err("refused").to_string(),
        "the message CRC does not match"
    );
}
