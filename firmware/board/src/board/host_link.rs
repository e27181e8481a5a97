//! The USB tasks: the embassy-usb device, and the CDC-ACM sender and receiver between the host
//! and the application's pipes.

use super::*;

#[embassy_executor::task]
pub(super) async fn usb_task(mut dev: embassy_usb::UsbDevice<'static, UsbDriver>) -> ! {
    dev.run().await
}

#[embassy_executor::task]
pub(super) async fn usb_tx_task(shared: &'static Shared, mut tx: Sender<'static, UsbDriver>) {
    let mut buf = [0u8; 64];
    loop {
        tx.wait_connection().await;
        // A clean start: bytes queued for a host that went away (a frame cut by the cable pull)
        // are dropped; what the application must resend, it resends from its run store.
        shared.tx.clear();
        shared.connected.store(true, Ordering::Release);
        defmt::info!("usb: host connected");
        loop {
            let n = shared.tx.read(&mut buf).await;
            if tx.write_packet(&buf[..n]).await.is_err() {
                break;
            }
        }
        shared.connected.store(false, Ordering::Release);
        defmt::info!("usb: host gone");
    }
}

#[embassy_executor::task]
pub(super) async fn usb_rx_task(shared: &'static Shared, mut rx: Receiver<'static, UsbDriver>) {
    let mut buf = [0u8; 64];
    loop {
        rx.wait_connection().await;
        // Packets of a previous connection not yet taken by the application are stale; the empty
        // packet tells the application a new connection starts here.
        shared.rx.clear();
        shared.rx.send(heapless::Vec::new()).await;
        while let Ok(n) = rx.read_packet(&mut buf).await {
            if n == 0 {
                continue;
            }
            let bytes = heapless::Vec::from_slice(&buf[..n]).unwrap_or_default();
            shared.rx.send(bytes).await;
        }
    }
}
