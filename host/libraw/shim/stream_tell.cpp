// The one C++ call the EXIF callback needs: where LibRaw's input stream stands, so the
// Rust side reads a tag's value from the bytes it handed to libraw_open_buffer.
// LibRaw's C API passes the stream to the callback as void*; its class is declared in the
// vendored libraw_datastream.h of the same LibRaw version rsraw-sys builds.
#include <stdint.h>
#include "libraw/libraw_datastream.h"

extern "C" int64_t skinbrdf_libraw_stream_tell(void *stream)
{
  if (stream == nullptr)
    return -1;
  return static_cast<LibRaw_abstract_datastream *>(stream)->tell();
}
