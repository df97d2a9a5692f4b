//! The little of GenICam GenApi the source needs from a camera: the
//! register of `PayloadSize` (when the data stream leaves the payload size
//! to the remote device) and of the `AcquisitionStart` / `AcquisitionStop`
//! commands. Reads the remote device's description file through its port
//! (`local:` URLs, uncompressed XML; or `file:`) and follows only the
//! simple chain feature → `pValue` → `IntReg` with a literal `Address`,
//! `Length` and `Endianess`. A camera described otherwise (zipped file,
//! computed addresses, masked registers) is reported as such: the source
//! then needs `payload_size` set and a free-running camera.

/// A register of the remote device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Register {
    /// Address on the remote device's port.
    pub address: u64,
    /// Bytes (1, 2, 4 or 8).
    pub length: usize,
    /// Little-endian (GenApi's default) or big-endian.
    pub little_endian: bool,
}

impl Register {
    /// The register's bytes of `value`.
    pub fn encode(&self, value: u64) -> Vec<u8> {
        let n = self.length.min(8);
        if self.little_endian {
            value.to_le_bytes()[..n].to_vec()
        } else {
            value.to_be_bytes()[8 - n..].to_vec()
        }
    }

    /// The value of the register's bytes.
    pub fn decode(&self, bytes: &[u8]) -> u64 {
        let n = self.length.min(8).min(bytes.len());
        let mut b = [0u8; 8];
        if self.little_endian {
            b[..n].copy_from_slice(&bytes[..n]);
            u64::from_le_bytes(b)
        } else {
            b[8 - n..].copy_from_slice(&bytes[..n]);
            u64::from_be_bytes(b)
        }
    }
}

/// Where a description file is: in the device's register space
/// (`local:NAME;ADDRESS;LENGTH`, hex numbers) or on disk (`file:PATH`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Url {
    /// In the device's register space.
    Local {
        /// The file's name (tells whether it is zipped).
        name: String,
        /// Address.
        address: u64,
        /// Bytes.
        length: usize,
    },
    /// A file on the host.
    File(String),
}

fn number(s: &str) -> Option<u64> {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    }
}

/// Parses a port URL.
pub fn parse_url(url: &str) -> Option<Url> {
    let url = url.split('?').next().unwrap_or(url).trim();
    if let Some(rest) = url.strip_prefix("local:") {
        let rest = rest.trim_start_matches('/');
        let mut parts = rest.split(';');
        let name = parts.next()?.to_string();
        let hex = |s: &str| {
            let s = s.trim();
            u64::from_str_radix(s.strip_prefix("0x").unwrap_or(s), 16).ok()
        };
        let address = hex(parts.next()?)?;
        let length = hex(parts.next()?)? as usize;
        return Some(Url::Local {
            name,
            address,
            length,
        });
    }
    url.strip_prefix("file:")
        .map(|p| Url::File(p.trim_start_matches("///").to_string()))
        .map(|u| match u {
            Url::File(p) if !p.starts_with('/') => Url::File(format!("/{p}")),
            u => u,
        })
}

/// The body of the element `<tag Name="name" ...>…</tag>`.
fn element<'a>(xml: &'a str, tag: &str, name: &str) -> Option<&'a str> {
    let open = format!("<{tag} Name=\"{name}\"");
    let start = xml.find(&open)? + open.len();
    let body = &xml[start..];
    let body = &body[body.find('>')? + 1..];
    let end = body.find(&format!("</{tag}>"))?;
    Some(&body[..end])
}

/// The text of the first `<tag>…</tag>` in `body`.
fn child<'a>(body: &'a str, tag: &str) -> Option<&'a str> {
    let open = format!("<{tag}>");
    let start = body.find(&open)? + open.len();
    let end = body[start..].find(&format!("</{tag}>"))?;
    Some(body[start..start + end].trim())
}

/// The `IntReg` named `name` (literal address, length, endianness).
fn int_reg(xml: &str, name: &str) -> Option<Register> {
    let body = element(xml, "IntReg", name)?;
    Some(Register {
        address: number(child(body, "Address")?)?,
        length: child(body, "Length").and_then(number).unwrap_or(4) as usize,
        little_endian: child(body, "Endianess") != Some("BigEndian"),
    })
}

/// The register holding the integer feature `feature`.
pub fn integer(xml: &str, feature: &str) -> Option<Register> {
    let body = element(xml, "Integer", feature)?;
    int_reg(xml, child(body, "pValue")?)
}

/// The register of the command `feature` and the value that executes it.
pub fn command(xml: &str, feature: &str) -> Option<(Register, u64)> {
    let body = element(xml, "Command", feature)?;
    let reg = int_reg(xml, child(body, "pValue")?)?;
    let value = child(body, "CommandValue").and_then(number).unwrap_or(1);
    Some((reg, value))
}

#[cfg(test)]
mod tests {
    use super::*;

    const XML: &str = r#"<RegisterDescription>
   <Integer Name="PayloadSize" NameSpace="Standard">
      <pValue>PayloadSize_Val</pValue>
   </Integer>
   <Command Name="AcquisitionStart" NameSpace="Standard">
      <pValue>AcquisitionStart_Val</pValue>
      <CommandValue>1</CommandValue>
   </Command>
   <IntReg Name="PayloadSize_Val">
      <Address>0x5000000C</Address>
      <Length>4</Length>
      <AccessMode>RO</AccessMode>
      <pPort>Device</pPort>
      <Endianess>LittleEndian</Endianess>
   </IntReg>
   <IntReg Name="AcquisitionStart_Val">
      <Address>0x50000010</Address>
      <Length>4</Length>
      <Endianess>BigEndian</Endianess>
   </IntReg>
</RegisterDescription>"#;

    #[test]
    fn features_lead_to_their_registers() {
        let p = integer(XML, "PayloadSize").unwrap();
        assert_eq!(
            (p.address, p.length, p.little_endian),
            (0x5000_000C, 4, true)
        );
        let (a, v) = command(XML, "AcquisitionStart").unwrap();
        assert_eq!((a.address, v, a.little_endian), (0x5000_0010, 1, false));
        assert_eq!(a.encode(1), vec![0, 0, 0, 1]);
        assert_eq!(p.encode(640_000), 640_000u32.to_le_bytes().to_vec());
        assert_eq!(p.decode(&640_000u32.to_le_bytes()), 640_000);
        assert_eq!(a.decode(&[0, 0, 2, 0]), 512);
        assert_eq!(command(XML, "AcquisitionStop"), None);
        assert_eq!(integer(XML, "Payload"), None);
    }

    #[test]
    fn port_urls_parse() {
        assert_eq!(
            parse_url("local:cam.xml;10000;2A0?SchemaVersion=1.1.0"),
            Some(Url::Local {
                name: "cam.xml".into(),
                address: 0x10000,
                length: 0x2A0
            })
        );
        assert_eq!(
            parse_url("file:///opt/cam.xml"),
            Some(Url::File("/opt/cam.xml".into()))
        );
        assert_eq!(parse_url("http://x/cam.xml"), None);
        assert_eq!(parse_url("local:cam.xml;zz;1"), None);
    }
}
