// Validation of an OpenEXR file's headers before OpenEXR reads them.
// OpenEXR's header reader trusts the file: it reads each attribute of a known
// type by the type's own layout (a channel list until its empty name, a box
// as four ints, ...) whatever size the attribute declares, so a value whose
// declared size disagrees with its content desynchronises the reading of
// everything after it, and sizes read from the wrong place are then
// allocated. CheckExrHeaders walks every header (all parts of a multi-part
// file) by the layout of the OpenEXR file format (docs/robustness.md),
// parses the value of every attribute type OpenEXR itself reads, and refuses
// a value whose parsed size differs from its declared size, a size running
// past the end of the file, and names or values OpenEXR would misread.
// Attributes of unknown types are bounded by the file size only. It also
// refuses a tile description or data window beyond the limits of the images
// vox writes, by which OpenEXR would allocate before reading any pixel.
//
// Thread safety: thread-safe (no shared state).
#ifndef VOX_RENDER_INTERNAL_EXR_HEADER_H_
#define VOX_RENDER_INTERNAL_EXR_HEADER_H_

#include <string>

#include "core/util/status.h"

namespace vox {

// Checks the headers of the EXR file at `path`. A file without OpenEXR's
// magic number passes (OpenEXR reports that itself); errors name `path` and,
// where one is at fault, the attribute and its type.
Status CheckExrHeaders(const std::string& path);

}  // namespace vox

#endif  // VOX_RENDER_INTERNAL_EXR_HEADER_H_
