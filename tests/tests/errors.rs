//! Every error of the libraries is a `core::error::Error` whose message says what went
//! wrong in words (the first sentence of the variant's documentation), so that an
//! application can report it, box it or `?` it into its own error type.

use can_gateway::secoc::AuthError;
use can_gateway::{DecodeError, EncodeError};
use planner_core::{ConfigError, InputError, LaneInputError, ParamsError, SolveError, WorldError};

fn says(e: &dyn core::error::Error, words: &str) {
    let text = e.to_string();
    assert!(text.contains(words), "{text:?} should say {words:?}");
}

#[test]
fn every_error_says_what_went_wrong() {
    says(&DecodeError::Crc, "CRC does not match");
    says(&DecodeError::Stale, "not newer");
    says(&DecodeError::Auth(AuthError::BadMac), "MAC does not match");
    says(&AuthError::UnknownKey, "no key");
    says(&EncodeError::Frame, "frame type refused");
    says(&WorldError::OwnMessage, "receiver's own");
    says(&ConfigError::InvalidLatency, "notification latency");
    says(&InputError::SpeedOutOfRange, "vmax");
    says(&LaneInputError::LaneTooNarrow, "not wider than the vehicle");
    says(&ParamsError::DecelerationNotNegative, "a_min must be < 0");
    says(&SolveError::NonFinite, "NaN");
    // A wrapped error says its cause, and gives it as its source.
    let e = LaneInputError::Speed(InputError::NotFinite);
    says(&e, "NaN or infinite");
    assert!(core::error::Error::source(&e).is_some());
}

#[test]
fn an_error_goes_into_an_applications_own() {
    fn decode() -> Result<(), Box<dyn std::error::Error>> {
        Err(DecodeError::Crc)?
    }
    assert_eq!(
        decode().expect_err("refused").to_string(),
        "the message CRC does not match"
    );
}
