// The page vox-view serves (page.html, embedded at build time).
#ifndef VOX_TOOLS_VIEW_PAGE_H_
#define VOX_TOOLS_VIEW_PAGE_H_

namespace vox {
extern const char kViewPage[];
}  // namespace vox

#endif  // VOX_TOOLS_VIEW_PAGE_H_
