"""The MCAP file format's constants (https://mcap.dev/spec): magic and record opcodes."""

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX = 0x06, 0x07, 0x08
OP_ATTACHMENT, OP_ATTACHMENT_INDEX = 0x09, 0x0A
OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX = 0x0B, 0x0C, 0x0D
OP_SUMMARY_OFFSET, OP_DATA_END = 0x0E, 0x0F
KNOWN_OPCODES = range(0x01, 0x11)  # the spec's opcodes (0x10: footer of an attachment list)
