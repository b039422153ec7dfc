//! `--display-server HOST:PORT`: the image streamed to the tev HDR viewer while it renders
//! (`reference` after every pass, every method's final image), over tev's TCP protocol through the
//! `tev_client` crate. A viewer that is not listening, or that goes away, is a warning: the render
//! goes on without it.

use crate::error::{Error, Result};
use crate::Image;
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::Mutex;
use std::time::Duration;
use tev_client::{PacketCreateImage, PacketUpdateImage, TevClient};

/// How long to wait for the viewer to accept the connection.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);

/// The channels sent: the image's RGB.
const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// A connection to tev, or none once it failed.
pub struct Display {
    client: Mutex<Option<TevClient>>,
    /// The image's name in tev.
    name: String,
    /// The size tev's image was created with.
    created: Mutex<Option<(u32, u32)>>,
}

/// The address `--display-server` names; an error names the flag and says whether the text is
/// not HOST:PORT or its host could not be resolved.
pub fn parse(addr: &str) -> Result<SocketAddr> {
    let bad = |why: String| Error::invalid("command line", "--display-server", why);
    let Some((host, _)) = addr.rsplit_once(':').filter(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok()) else {
        return Err(bad(format!(
            "`{addr}` is not HOST:PORT of a tev viewer (e.g. 127.0.0.1:14158, tev's default)"
        )));
    };
    let unresolved = |why: String| {
        bad(format!(
            "the host `{host}` could not be resolved ({why}); check its name, or give the viewer's IP address \
             (e.g. 127.0.0.1:14158)"
        ))
    };
    match addr.to_socket_addrs() {
        Ok(mut found) => found.next().ok_or_else(|| unresolved("it has no address".into())),
        Err(e) => Err(unresolved(e.to_string())),
    }
}

impl Display {
    /// Connect to tev at `addr`, naming the image `name`; None (with a warning on stderr) when
    /// nothing listens there.
    pub fn connect(addr: SocketAddr, name: &str) -> Option<Display> {
        match TcpStream::connect_timeout(&addr, CONNECT_TIMEOUT) {
            Ok(socket) => Some(Display {
                client: Mutex::new(Some(TevClient::wrap(socket))),
                name: name.to_string(),
                created: Mutex::new(None),
            }),
            Err(e) => {
                note!(
                    "warning: --display-server {addr}: cannot reach a tev viewer ({e}); rendering without the live view \
                     (start one with `tev --hostname {addr}`)"
                );
                None
            }
        }
    }

    /// Send `img` (creating tev's image on the first call or a new size).
    pub fn show(&self, img: &Image) {
        let Ok(mut client) = self.client.lock() else { return };
        let Some(c) = client.as_mut() else { return };
        let Ok(mut created) = self.created.lock() else { return };
        let size = (img.width, img.height);
        let data: Vec<f32> = img.pixels.iter().flat_map(|p| p.to_array()).collect();
        let mut sent = Ok(());
        if *created != Some(size) {
            sent = c.send(PacketCreateImage {
                image_name: &self.name,
                grab_focus: true,
                width: img.width,
                height: img.height,
                channel_names: &CHANNELS,
            });
            *created = Some(size);
        }
        if sent.is_ok() && !data.is_empty() {
            sent = c.send(PacketUpdateImage {
                image_name: &self.name,
                grab_focus: false,
                channel_names: &CHANNELS,
                channel_offsets: &[0, 1, 2],
                channel_strides: &[3, 3, 3],
                x: 0,
                y: 0,
                width: img.width,
                height: img.height,
                data: &data,
            });
        }
        if let Err(e) = sent {
            note!("warning: --display-server: the tev viewer went away ({e}); rendering goes on without it");
            *client = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_malformed_address_and_an_unknown_host_are_told_apart() {
        assert_eq!(parse("127.0.0.1:14158").unwrap().port(), 14158);
        for malformed in ["nowhere", "localhost:", ":14158", "localhost:99999", "localhost:port"] {
            let e = parse(malformed).unwrap_err().to_string();
            assert!(e.contains("--display-server") && e.contains("is not HOST:PORT"), "{malformed}: {e}");
        }
        // `.invalid` never resolves (RFC 2606).
        let e = parse("viewer.invalid:14158").unwrap_err().to_string();
        assert!(
            e.contains("the host `viewer.invalid` could not be resolved") && !e.contains("HOST:PORT"),
            "{e}"
        );
    }
}
