//! [`Codec`], the codec of every generated service and client:
//! tonic-prost's, except that bytes that do not decode as the expected
//! message answer INVALID_ARGUMENT (tonic-prost says INTERNAL, which
//! blames the receiver for what the sender got wrong), naming the message.

use std::any::type_name;

use prost::Message;
use tonic::Status;
use tonic::codec::{BufferSettings, Codec as TonicCodec, DecodeBuf, Decoder};
use tonic_prost::{ProstCodec, ProstDecoder};

/// tonic-prost's codec with [`DecoderInvalidArgument`] as its decoder;
/// `proto/build.rs` makes every service use it (`codec_path`).
#[derive(Debug, Clone)]
pub struct Codec<T, U>(ProstCodec<T, U>);

impl<T, U> Default for Codec<T, U> {
    fn default() -> Self {
        Self(ProstCodec::default())
    }
}

impl<T, U> TonicCodec for Codec<T, U>
where
    T: Message + Send + 'static,
    U: Message + Default + Send + 'static,
{
    type Encode = T;
    type Decode = U;
    type Encoder = <ProstCodec<T, U> as TonicCodec>::Encoder;
    type Decoder = DecoderInvalidArgument<U>;

    fn encoder(&mut self) -> Self::Encoder {
        self.0.encoder()
    }

    fn decoder(&mut self) -> Self::Decoder {
        DecoderInvalidArgument(self.0.decoder())
    }
}

/// tonic-prost's decoder whose decode errors are INVALID_ARGUMENT.
#[derive(Debug, Clone)]
pub struct DecoderInvalidArgument<U>(ProstDecoder<U>);

impl<U: Message + Default> Decoder for DecoderInvalidArgument<U> {
    type Item = U;
    type Error = Status;

    fn decode(&mut self, buf: &mut DecodeBuf<'_>) -> Result<Option<U>, Status> {
        self.0.decode(buf).map_err(|status| {
            let name = type_name::<U>().rsplit("::").next().unwrap_or("message");
            Status::invalid_argument(format!(
                "the message did not decode as protobuf crossroads.v1.{name}: {}",
                status.message()
            ))
        })
    }

    fn buffer_settings(&self) -> BufferSettings {
        self.0.buffer_settings()
    }
}
