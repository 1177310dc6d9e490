#include "shell_shape.h"

#include <algorithm>

namespace softshell::bullet::internal {

void ShellShape::refit(const float* positions, const int* indices, const btVector3& lo, const btVector3& hi,
                       btScalar quantization_margin) {
  btOptimizedBvh& bvh = *getOptimizedBvh();
  bvh.setQuantizationValues(lo, hi, quantization_margin);
  QuantizedNodeArray& nodes = bvh.getQuantizedNodeArray();
  const int count = nodes[0].isLeafNode() ? 1 : nodes[0].getEscapeIndex();

  // Children have larger indices than their parent: one pass from the back.
  for (int i = count - 1; i >= 0; --i) {
    btQuantizedBvhNode& node = nodes[i];
    if (node.isLeafNode()) {
      const int* tri = indices + 3 * node.getTriangleIndex();
      const float* a = positions + 3 * tri[0];
      const float* b = positions + 3 * tri[1];
      const float* c = positions + 3 * tri[2];
      const btVector3 min(std::min({a[0], b[0], c[0]}), std::min({a[1], b[1], c[1]}), std::min({a[2], b[2], c[2]}));
      const btVector3 max(std::max({a[0], b[0], c[0]}), std::max({a[1], b[1], c[1]}), std::max({a[2], b[2], c[2]}));
      bvh.quantizeWithClamp(node.m_quantizedAabbMin, min, 0);
      bvh.quantizeWithClamp(node.m_quantizedAabbMax, max, 1);
    } else {
      const btQuantizedBvhNode& left = nodes[i + 1];
      const btQuantizedBvhNode& right = left.isLeafNode() ? nodes[i + 2] : nodes[i + 1 + left.getEscapeIndex()];
      for (int k = 0; k < 3; ++k) {
        node.m_quantizedAabbMin[k] = std::min(left.m_quantizedAabbMin[k], right.m_quantizedAabbMin[k]);
        node.m_quantizedAabbMax[k] = std::max(left.m_quantizedAabbMax[k], right.m_quantizedAabbMax[k]);
      }
    }
  }
  BvhSubtreeInfoArray& subtrees = bvh.getSubtreeInfoArray();
  for (int s = 0; s < subtrees.size(); ++s) subtrees[s].setAabbFromQuantizeNode(nodes[subtrees[s].m_rootNodeIndex]);

  // The shape's own bounds (what recalcLocalAabb would find, without its six full passes).
  m_localAabbMin = lo;
  m_localAabbMax = hi;
}

}  // namespace softshell::bullet::internal
