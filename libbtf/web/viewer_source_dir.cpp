// The viewer folder of this source tree (the default of BrowserOptions::viewer_dir), alone in its
// file: the path differs between checkouts, and as a definition on web.cpp it would make ccache
// miss that file in every fresh clone (CI's).
namespace btf {
const char* ViewerSourceDir() { return BTF_VIEWER_SOURCE_DIR; }
}  // namespace btf
