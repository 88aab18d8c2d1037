"""The host side of the controller's serial link: frame codec (:mod:`ikseries.host.protocol`)."""
from .protocol import (CRCTable, Decoder, FrameParser, Message, crc, decode_request, encode, encode_answer,
                       frame, request_parser)

__all__ = ["CRCTable", "Decoder", "FrameParser", "Message", "crc", "decode_request", "encode", "encode_answer",
           "frame", "request_parser"]
