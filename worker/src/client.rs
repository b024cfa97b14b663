//! The worker's gRPC client: connection (http or https) with bearer token, and exponential
//! backoff for reconnecting and retrying.

use std::time::Duration;
use tessera_link::connect::Target;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;
use tonic::transport::Channel;

/// A connected client plus its token.
#[derive(Clone)]
pub struct Client {
    /// The gRPC client.
    pub inner: WorkerServiceClient<Channel>,
    token: Option<String>,
}

impl Client {
    /// Connects to the coordinator at `endpoint` (see [`tessera_link::connect::endpoint`]).
    pub async fn connect(endpoint: &Target, token: Option<String>) -> Result<Client, tonic::transport::Error> {
        let channel = endpoint.clone().connect_timeout(Duration::from_secs(5)).connect().await?;
        let inner = WorkerServiceClient::new(channel)
            .max_decoding_message_size(tessera_proto::MAX_MESSAGE_BYTES)
            .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
        Ok(Client { inner, token })
    }

    /// Wraps a message (or stream) with the bearer token.
    pub fn request<T>(&self, message: T) -> tonic::Request<T> {
        tessera_proto::authorized(message, self.token.as_deref())
    }
}

/// Exponential backoff from 100 ms to 5 s.
#[derive(Clone, Debug, Default)]
pub struct Backoff {
    attempt: u32,
}

impl Backoff {
    /// The next delay.
    pub fn next_delay(&mut self) -> Duration {
        let d = Duration::from_millis(100u64 << self.attempt.min(6)).min(Duration::from_secs(5));
        self.attempt += 1;
        d
    }

    /// Back to the shortest delay after a success.
    pub fn reset(&mut self) {
        self.attempt = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_grows_to_a_cap_and_resets() {
        let mut b = Backoff::default();
        let delays: Vec<_> = (0..9).map(|_| b.next_delay().as_millis()).collect();
        assert_eq!(delays, vec![100, 200, 400, 800, 1600, 3200, 5000, 5000, 5000]);
        b.reset();
        assert_eq!(b.next_delay().as_millis(), 100);
    }
}
