//! The part of the EMVA GenTL C interface (standard versions 1.5/1.6) that
//! photopose uses: handle and value types, the numeric values of the error
//! codes, info commands and flags, and the signature of every call, as the
//! standard defines them. Plain declarations, no code: the consumer's loader
//! (`ffi`) and the workspace's test producer both build on them.
//!
//! All calls use the C calling convention (`GC_CALLTYPE` is empty on
//! Linux); strings are NUL-terminated, sizes are in bytes and include the
//! terminating NUL.

#![allow(non_camel_case_types, non_snake_case, missing_docs)]

use std::ffi::{c_char, c_void};

/// Result of every call: 0 on success, a negative `GC_ERR_*` otherwise.
pub type GC_ERROR = i32;
/// GenTL's one-byte boolean.
pub type bool8_t = u8;

/// Opaque handles of the GenTL modules.
pub type TL_HANDLE = *mut c_void;
pub type IF_HANDLE = *mut c_void;
pub type DEV_HANDLE = *mut c_void;
pub type DS_HANDLE = *mut c_void;
pub type PORT_HANDLE = *mut c_void;
pub type BUFFER_HANDLE = *mut c_void;
pub type EVENT_HANDLE = *mut c_void;
pub type EVENTSRC_HANDLE = *mut c_void;

pub type INFO_DATATYPE = i32;
pub type TL_INFO_CMD = i32;
pub type INTERFACE_INFO_CMD = i32;
pub type DEVICE_INFO_CMD = i32;
pub type DEVICE_ACCESS_FLAGS = i32;
pub type STREAM_INFO_CMD = i32;
pub type BUFFER_INFO_CMD = i32;
pub type ACQ_START_FLAGS = i32;
pub type ACQ_STOP_FLAGS = i32;
pub type ACQ_QUEUE_TYPE = i32;
pub type EVENT_TYPE = i32;

/// A wait without end (`GENTL_INFINITE`).
pub const GENTL_INFINITE: u64 = u64::MAX;

// Error codes.
pub const GC_ERR_SUCCESS: GC_ERROR = 0;
pub const GC_ERR_ERROR: GC_ERROR = -1001;
pub const GC_ERR_NOT_INITIALIZED: GC_ERROR = -1002;
pub const GC_ERR_NOT_IMPLEMENTED: GC_ERROR = -1003;
pub const GC_ERR_RESOURCE_IN_USE: GC_ERROR = -1004;
pub const GC_ERR_ACCESS_DENIED: GC_ERROR = -1005;
pub const GC_ERR_INVALID_HANDLE: GC_ERROR = -1006;
pub const GC_ERR_INVALID_ID: GC_ERROR = -1007;
pub const GC_ERR_NO_DATA: GC_ERROR = -1008;
pub const GC_ERR_INVALID_PARAMETER: GC_ERROR = -1009;
pub const GC_ERR_IO: GC_ERROR = -1010;
pub const GC_ERR_TIMEOUT: GC_ERROR = -1011;
pub const GC_ERR_ABORT: GC_ERROR = -1012;
pub const GC_ERR_INVALID_BUFFER: GC_ERROR = -1013;
pub const GC_ERR_NOT_AVAILABLE: GC_ERROR = -1014;
pub const GC_ERR_INVALID_ADDRESS: GC_ERROR = -1015;
pub const GC_ERR_BUFFER_TOO_SMALL: GC_ERROR = -1016;
pub const GC_ERR_INVALID_INDEX: GC_ERROR = -1017;
pub const GC_ERR_PARSING_CHUNK_DATA: GC_ERROR = -1018;
pub const GC_ERR_INVALID_VALUE: GC_ERROR = -1019;
pub const GC_ERR_RESOURCE_EXHAUSTED: GC_ERROR = -1020;
pub const GC_ERR_OUT_OF_MEMORY: GC_ERROR = -1021;
pub const GC_ERR_BUSY: GC_ERROR = -1022;
pub const GC_ERR_AMBIGUOUS: GC_ERROR = -1023;

/// The standard's name of an error code (for messages).
pub fn error_name(code: GC_ERROR) -> &'static str {
    match code {
        GC_ERR_SUCCESS => "GC_ERR_SUCCESS",
        GC_ERR_ERROR => "GC_ERR_ERROR",
        GC_ERR_NOT_INITIALIZED => "GC_ERR_NOT_INITIALIZED",
        GC_ERR_NOT_IMPLEMENTED => "GC_ERR_NOT_IMPLEMENTED",
        GC_ERR_RESOURCE_IN_USE => "GC_ERR_RESOURCE_IN_USE",
        GC_ERR_ACCESS_DENIED => "GC_ERR_ACCESS_DENIED",
        GC_ERR_INVALID_HANDLE => "GC_ERR_INVALID_HANDLE",
        GC_ERR_INVALID_ID => "GC_ERR_INVALID_ID",
        GC_ERR_NO_DATA => "GC_ERR_NO_DATA",
        GC_ERR_INVALID_PARAMETER => "GC_ERR_INVALID_PARAMETER",
        GC_ERR_IO => "GC_ERR_IO",
        GC_ERR_TIMEOUT => "GC_ERR_TIMEOUT",
        GC_ERR_ABORT => "GC_ERR_ABORT",
        GC_ERR_INVALID_BUFFER => "GC_ERR_INVALID_BUFFER",
        GC_ERR_NOT_AVAILABLE => "GC_ERR_NOT_AVAILABLE",
        GC_ERR_INVALID_ADDRESS => "GC_ERR_INVALID_ADDRESS",
        GC_ERR_BUFFER_TOO_SMALL => "GC_ERR_BUFFER_TOO_SMALL",
        GC_ERR_INVALID_INDEX => "GC_ERR_INVALID_INDEX",
        GC_ERR_PARSING_CHUNK_DATA => "GC_ERR_PARSING_CHUNK_DATA",
        GC_ERR_INVALID_VALUE => "GC_ERR_INVALID_VALUE",
        GC_ERR_RESOURCE_EXHAUSTED => "GC_ERR_RESOURCE_EXHAUSTED",
        GC_ERR_OUT_OF_MEMORY => "GC_ERR_OUT_OF_MEMORY",
        GC_ERR_BUSY => "GC_ERR_BUSY",
        GC_ERR_AMBIGUOUS => "GC_ERR_AMBIGUOUS",
        _ => "vendor error",
    }
}

// INFO_DATATYPE.
pub const INFO_DATATYPE_UNKNOWN: INFO_DATATYPE = 0;
pub const INFO_DATATYPE_STRING: INFO_DATATYPE = 1;
pub const INFO_DATATYPE_INT32: INFO_DATATYPE = 5;
pub const INFO_DATATYPE_UINT32: INFO_DATATYPE = 6;
pub const INFO_DATATYPE_INT64: INFO_DATATYPE = 7;
pub const INFO_DATATYPE_UINT64: INFO_DATATYPE = 8;
pub const INFO_DATATYPE_PTR: INFO_DATATYPE = 10;
pub const INFO_DATATYPE_BOOL8: INFO_DATATYPE = 11;
pub const INFO_DATATYPE_SIZET: INFO_DATATYPE = 12;

// TL_INFO_CMD (also for GCGetInfo).
pub const TL_INFO_ID: TL_INFO_CMD = 0;
pub const TL_INFO_VENDOR: TL_INFO_CMD = 1;
pub const TL_INFO_MODEL: TL_INFO_CMD = 2;
pub const TL_INFO_VERSION: TL_INFO_CMD = 3;
pub const TL_INFO_TLTYPE: TL_INFO_CMD = 4;

// INTERFACE_INFO_CMD.
pub const INTERFACE_INFO_ID: INTERFACE_INFO_CMD = 0;
pub const INTERFACE_INFO_DISPLAYNAME: INTERFACE_INFO_CMD = 1;
pub const INTERFACE_INFO_TLTYPE: INTERFACE_INFO_CMD = 2;

// DEVICE_INFO_CMD.
pub const DEVICE_INFO_ID: DEVICE_INFO_CMD = 0;
pub const DEVICE_INFO_VENDOR: DEVICE_INFO_CMD = 1;
pub const DEVICE_INFO_MODEL: DEVICE_INFO_CMD = 2;
pub const DEVICE_INFO_TLTYPE: DEVICE_INFO_CMD = 3;
pub const DEVICE_INFO_DISPLAYNAME: DEVICE_INFO_CMD = 4;
pub const DEVICE_INFO_ACCESS_STATUS: DEVICE_INFO_CMD = 5;
pub const DEVICE_INFO_USER_DEFINED_NAME: DEVICE_INFO_CMD = 6;
pub const DEVICE_INFO_SERIAL_NUMBER: DEVICE_INFO_CMD = 7;
pub const DEVICE_INFO_VERSION: DEVICE_INFO_CMD = 8;
pub const DEVICE_INFO_TIMESTAMP_FREQUENCY: DEVICE_INFO_CMD = 9;

// DEVICE_ACCESS_FLAGS.
pub const DEVICE_ACCESS_READONLY: DEVICE_ACCESS_FLAGS = 2;
pub const DEVICE_ACCESS_CONTROL: DEVICE_ACCESS_FLAGS = 3;
pub const DEVICE_ACCESS_EXCLUSIVE: DEVICE_ACCESS_FLAGS = 4;

// STREAM_INFO_CMD.
pub const STREAM_INFO_ID: STREAM_INFO_CMD = 0;
pub const STREAM_INFO_NUM_DELIVERED: STREAM_INFO_CMD = 1;
pub const STREAM_INFO_NUM_UNDERRUN: STREAM_INFO_CMD = 2;
pub const STREAM_INFO_NUM_ANNOUNCED: STREAM_INFO_CMD = 3;
pub const STREAM_INFO_NUM_QUEUED: STREAM_INFO_CMD = 4;
pub const STREAM_INFO_NUM_AWAIT_DELIVERY: STREAM_INFO_CMD = 5;
pub const STREAM_INFO_NUM_STARTED: STREAM_INFO_CMD = 6;
pub const STREAM_INFO_PAYLOAD_SIZE: STREAM_INFO_CMD = 7;
pub const STREAM_INFO_IS_GRABBING: STREAM_INFO_CMD = 8;
pub const STREAM_INFO_DEFINES_PAYLOADSIZE: STREAM_INFO_CMD = 9;
pub const STREAM_INFO_BUF_ANNOUNCE_MIN: STREAM_INFO_CMD = 12;
pub const STREAM_INFO_BUF_ALIGNMENT: STREAM_INFO_CMD = 13;

// BUFFER_INFO_CMD.
pub const BUFFER_INFO_BASE: BUFFER_INFO_CMD = 0;
pub const BUFFER_INFO_SIZE: BUFFER_INFO_CMD = 1;
pub const BUFFER_INFO_USER_PTR: BUFFER_INFO_CMD = 2;
pub const BUFFER_INFO_TIMESTAMP: BUFFER_INFO_CMD = 3;
pub const BUFFER_INFO_NEW_DATA: BUFFER_INFO_CMD = 4;
pub const BUFFER_INFO_IS_QUEUED: BUFFER_INFO_CMD = 5;
pub const BUFFER_INFO_IS_ACQUIRING: BUFFER_INFO_CMD = 6;
pub const BUFFER_INFO_IS_INCOMPLETE: BUFFER_INFO_CMD = 7;
pub const BUFFER_INFO_TLTYPE: BUFFER_INFO_CMD = 8;
pub const BUFFER_INFO_SIZE_FILLED: BUFFER_INFO_CMD = 9;
pub const BUFFER_INFO_WIDTH: BUFFER_INFO_CMD = 10;
pub const BUFFER_INFO_HEIGHT: BUFFER_INFO_CMD = 11;
pub const BUFFER_INFO_XOFFSET: BUFFER_INFO_CMD = 12;
pub const BUFFER_INFO_YOFFSET: BUFFER_INFO_CMD = 13;
pub const BUFFER_INFO_XPADDING: BUFFER_INFO_CMD = 14;
pub const BUFFER_INFO_YPADDING: BUFFER_INFO_CMD = 15;
pub const BUFFER_INFO_FRAMEID: BUFFER_INFO_CMD = 16;
pub const BUFFER_INFO_IMAGEPRESENT: BUFFER_INFO_CMD = 17;
pub const BUFFER_INFO_IMAGEOFFSET: BUFFER_INFO_CMD = 18;
pub const BUFFER_INFO_PAYLOADTYPE: BUFFER_INFO_CMD = 19;
pub const BUFFER_INFO_PIXELFORMAT: BUFFER_INFO_CMD = 20;
pub const BUFFER_INFO_PIXELFORMAT_NAMESPACE: BUFFER_INFO_CMD = 21;
pub const BUFFER_INFO_DELIVERED_IMAGEHEIGHT: BUFFER_INFO_CMD = 22;
pub const BUFFER_INFO_PIXEL_ENDIANNESS: BUFFER_INFO_CMD = 26;
pub const BUFFER_INFO_DATA_SIZE: BUFFER_INFO_CMD = 27;
pub const BUFFER_INFO_TIMESTAMP_NS: BUFFER_INFO_CMD = 28;

// PIXELFORMAT_NAMESPACE values (BUFFER_INFO_PIXELFORMAT_NAMESPACE).
pub const PIXELFORMAT_NAMESPACE_UNKNOWN: u64 = 0;
pub const PIXELFORMAT_NAMESPACE_GEV: u64 = 1;
pub const PIXELFORMAT_NAMESPACE_IIDC: u64 = 2;
pub const PIXELFORMAT_NAMESPACE_CUSTOM: u64 = 3;
pub const PIXELFORMAT_NAMESPACE_PFNC_16BIT: u64 = 4;
pub const PIXELFORMAT_NAMESPACE_PFNC_32BIT: u64 = 5;

// PAYLOADTYPE values (BUFFER_INFO_PAYLOADTYPE).
pub const PAYLOAD_TYPE_UNKNOWN: u64 = 0;
pub const PAYLOAD_TYPE_IMAGE: u64 = 1;
pub const PAYLOAD_TYPE_CHUNK_DATA: u64 = 4;

// Acquisition flags and queue operations.
pub const ACQ_START_FLAGS_DEFAULT: ACQ_START_FLAGS = 0;
pub const ACQ_STOP_FLAGS_DEFAULT: ACQ_STOP_FLAGS = 0;
pub const ACQ_STOP_FLAGS_KILL: ACQ_STOP_FLAGS = 1;
pub const ACQ_QUEUE_INPUT_TO_OUTPUT: ACQ_QUEUE_TYPE = 0;
pub const ACQ_QUEUE_OUTPUT_DISCARD: ACQ_QUEUE_TYPE = 1;
pub const ACQ_QUEUE_ALL_TO_INPUT: ACQ_QUEUE_TYPE = 2;
pub const ACQ_QUEUE_UNQUEUED_TO_INPUT: ACQ_QUEUE_TYPE = 3;
pub const ACQ_QUEUE_ALL_DISCARD: ACQ_QUEUE_TYPE = 4;

// EVENT_TYPE.
pub const EVENT_ERROR: EVENT_TYPE = 0;
pub const EVENT_NEW_BUFFER: EVENT_TYPE = 1;

/// What `EventGetData` writes for an `EVENT_NEW_BUFFER` event (the
/// standard packs its structures to 1 byte; two pointers need no padding).
#[repr(C, packed)]
#[derive(Debug, Clone, Copy)]
pub struct EVENT_NEW_BUFFER_DATA {
    pub BufferHandle: BUFFER_HANDLE,
    pub pUserPointer: *mut c_void,
}

// The calls (function pointer types, one per exported symbol).
pub type GCInitLib = unsafe extern "C" fn() -> GC_ERROR;
pub type GCCloseLib = unsafe extern "C" fn() -> GC_ERROR;
pub type GCGetInfo = unsafe extern "C" fn(
    info: TL_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    buffer: *mut c_void,
    size: *mut usize,
) -> GC_ERROR;
pub type GCGetLastError =
    unsafe extern "C" fn(code: *mut GC_ERROR, text: *mut c_char, size: *mut usize) -> GC_ERROR;
pub type GCReadPort = unsafe extern "C" fn(
    port: PORT_HANDLE,
    address: u64,
    buffer: *mut c_void,
    size: *mut usize,
) -> GC_ERROR;
pub type GCWritePort = unsafe extern "C" fn(
    port: PORT_HANDLE,
    address: u64,
    buffer: *const c_void,
    size: *mut usize,
) -> GC_ERROR;
pub type GCGetPortURL =
    unsafe extern "C" fn(port: PORT_HANDLE, url: *mut c_char, size: *mut usize) -> GC_ERROR;
pub type GCRegisterEvent = unsafe extern "C" fn(
    source: EVENTSRC_HANDLE,
    event: EVENT_TYPE,
    handle: *mut EVENT_HANDLE,
) -> GC_ERROR;
pub type GCUnregisterEvent =
    unsafe extern "C" fn(source: EVENTSRC_HANDLE, event: EVENT_TYPE) -> GC_ERROR;
pub type EventGetData = unsafe extern "C" fn(
    event: EVENT_HANDLE,
    buffer: *mut c_void,
    size: *mut usize,
    timeout_ms: u64,
) -> GC_ERROR;
pub type EventFlush = unsafe extern "C" fn(event: EVENT_HANDLE) -> GC_ERROR;
pub type EventKill = unsafe extern "C" fn(event: EVENT_HANDLE) -> GC_ERROR;

pub type TLOpen = unsafe extern "C" fn(tl: *mut TL_HANDLE) -> GC_ERROR;
pub type TLClose = unsafe extern "C" fn(tl: TL_HANDLE) -> GC_ERROR;
pub type TLGetInfo = unsafe extern "C" fn(
    tl: TL_HANDLE,
    info: TL_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    buffer: *mut c_void,
    size: *mut usize,
) -> GC_ERROR;
pub type TLUpdateInterfaceList =
    unsafe extern "C" fn(tl: TL_HANDLE, changed: *mut bool8_t, timeout_ms: u64) -> GC_ERROR;
pub type TLGetNumInterfaces = unsafe extern "C" fn(tl: TL_HANDLE, n: *mut u32) -> GC_ERROR;
pub type TLGetInterfaceID =
    unsafe extern "C" fn(tl: TL_HANDLE, index: u32, id: *mut c_char, size: *mut usize) -> GC_ERROR;
pub type TLOpenInterface =
    unsafe extern "C" fn(tl: TL_HANDLE, id: *const c_char, iface: *mut IF_HANDLE) -> GC_ERROR;

pub type IFClose = unsafe extern "C" fn(iface: IF_HANDLE) -> GC_ERROR;
pub type IFUpdateDeviceList =
    unsafe extern "C" fn(iface: IF_HANDLE, changed: *mut bool8_t, timeout_ms: u64) -> GC_ERROR;
pub type IFGetNumDevices = unsafe extern "C" fn(iface: IF_HANDLE, n: *mut u32) -> GC_ERROR;
pub type IFGetDeviceID = unsafe extern "C" fn(
    iface: IF_HANDLE,
    index: u32,
    id: *mut c_char,
    size: *mut usize,
) -> GC_ERROR;
pub type IFGetDeviceInfo = unsafe extern "C" fn(
    iface: IF_HANDLE,
    id: *const c_char,
    info: DEVICE_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    buffer: *mut c_void,
    size: *mut usize,
) -> GC_ERROR;
pub type IFOpenDevice = unsafe extern "C" fn(
    iface: IF_HANDLE,
    id: *const c_char,
    flags: DEVICE_ACCESS_FLAGS,
    device: *mut DEV_HANDLE,
) -> GC_ERROR;

pub type DevClose = unsafe extern "C" fn(device: DEV_HANDLE) -> GC_ERROR;
pub type DevGetPort = unsafe extern "C" fn(device: DEV_HANDLE, port: *mut PORT_HANDLE) -> GC_ERROR;
pub type DevGetNumDataStreams = unsafe extern "C" fn(device: DEV_HANDLE, n: *mut u32) -> GC_ERROR;
pub type DevGetDataStreamID = unsafe extern "C" fn(
    device: DEV_HANDLE,
    index: u32,
    id: *mut c_char,
    size: *mut usize,
) -> GC_ERROR;
pub type DevOpenDataStream =
    unsafe extern "C" fn(device: DEV_HANDLE, id: *const c_char, ds: *mut DS_HANDLE) -> GC_ERROR;

pub type DSClose = unsafe extern "C" fn(ds: DS_HANDLE) -> GC_ERROR;
pub type DSGetInfo = unsafe extern "C" fn(
    ds: DS_HANDLE,
    info: STREAM_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    buffer: *mut c_void,
    size: *mut usize,
) -> GC_ERROR;
pub type DSAnnounceBuffer = unsafe extern "C" fn(
    ds: DS_HANDLE,
    memory: *mut c_void,
    size: usize,
    private: *mut c_void,
    buffer: *mut BUFFER_HANDLE,
) -> GC_ERROR;
pub type DSAllocAndAnnounceBuffer = unsafe extern "C" fn(
    ds: DS_HANDLE,
    size: usize,
    private: *mut c_void,
    buffer: *mut BUFFER_HANDLE,
) -> GC_ERROR;
pub type DSRevokeBuffer = unsafe extern "C" fn(
    ds: DS_HANDLE,
    buffer: BUFFER_HANDLE,
    memory: *mut *mut c_void,
    private: *mut *mut c_void,
) -> GC_ERROR;
pub type DSQueueBuffer = unsafe extern "C" fn(ds: DS_HANDLE, buffer: BUFFER_HANDLE) -> GC_ERROR;
pub type DSFlushQueue = unsafe extern "C" fn(ds: DS_HANDLE, op: ACQ_QUEUE_TYPE) -> GC_ERROR;
pub type DSStartAcquisition =
    unsafe extern "C" fn(ds: DS_HANDLE, flags: ACQ_START_FLAGS, count: u64) -> GC_ERROR;
pub type DSStopAcquisition = unsafe extern "C" fn(ds: DS_HANDLE, flags: ACQ_STOP_FLAGS) -> GC_ERROR;
pub type DSGetBufferInfo = unsafe extern "C" fn(
    ds: DS_HANDLE,
    buffer: BUFFER_HANDLE,
    info: BUFFER_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    out: *mut c_void,
    size: *mut usize,
) -> GC_ERROR;
