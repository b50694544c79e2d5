// The scene's bodies (protocol 1.9, SceneDescription.bodies): each a slice of the description's arrays.
// The page draws them as one surface; this names them in the scene panel, with what each shows.

// "" for a scene of one body (or a server before 1.9, which lists none); else each body's name with its
// triangles (the fine surface's where it has one, else its boundary's).
/**
 * @param {{ name: string | Uint8Array | null, triangleBegin: number, triangleEnd: number,
 *           fineTriangleBegin: number, fineTriangleEnd: number }[] | null | undefined} bodies
 */
export function describeBodies(bodies) {
  if (!bodies || bodies.length < 2) return '';
  const parts = bodies.map((b) => {
    const fine = b.fineTriangleEnd - b.fineTriangleBegin;
    const triangles = fine > 0 ? fine : b.triangleEnd - b.triangleBegin;
    return `${b.name || '?'} (${triangles} triangles)`;
  });
  return `${bodies.length} bodies: ${parts.join(', ')}`;
}
