//! [`Worker`]: the background half of a [`Pusher`](crate::Pusher) or a
//! [`WeightsSubscription`](crate::WeightsSubscription), a tokio task or,
//! where an iceoryx2 port lives (ports are not `Send`), a thread of its
//! own.

use crate::error::ActorError;

/// A background task or thread; its owner stops it (through a `Shutdown`)
/// and then [`join`](Self::join)s it.
#[derive(Debug)]
pub(crate) enum Worker {
    /// On the tokio runtime.
    Task(tokio::task::JoinHandle<()>),
    /// On a thread of its own.
    Thread(std::thread::JoinHandle<()>),
}

impl Worker {
    /// Runs `f` on a thread named `name`; `what` names it in the error.
    pub(crate) fn thread(
        name: &str,
        what: &str,
        f: impl FnOnce() + Send + 'static,
    ) -> Result<Self, ActorError> {
        std::thread::Builder::new()
            .name(name.to_owned())
            .spawn(f)
            .map(Worker::Thread)
            .map_err(|e| ActorError::Config(format!("cannot start the {what} thread: {e}")))
    }

    /// Waits until the worker has ended (a thread is joined off the
    /// runtime's threads); an error says how it failed.
    pub(crate) async fn join(self) -> Result<(), String> {
        match self {
            Worker::Task(task) => task.await.map_err(|e| e.to_string()),
            Worker::Thread(thread) => {
                match tokio::task::spawn_blocking(move || thread.join()).await {
                    Ok(Ok(())) => Ok(()),
                    Ok(Err(_)) => Err("the thread panicked".to_owned()),
                    Err(e) => Err(e.to_string()),
                }
            }
        }
    }
}
