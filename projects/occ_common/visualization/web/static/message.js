// Reading of one sample's message (scene_payload.py writes it): the JSON
// header and typed-array views of its sections, without copies.

const MAGIC = 'OCCV';
export const FORMAT_VERSION = 1;
const ARRAYS = {uint8: Uint8Array, int16: Int16Array, uint32: Uint32Array,
                float32: Float32Array};

export function decodeMessage(buffer) {
  const bytes = new Uint8Array(buffer);
  const magic = String.fromCharCode(...bytes.subarray(0, 4));
  if (magic !== MAGIC) {
    throw new Error(`not a viewer message (starts with "${magic}")`);
  }
  const length = new DataView(buffer).getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(
      bytes.subarray(8, 8 + length)));
  if (header.version !== FORMAT_VERSION) {
    throw new Error(`viewer message version ${header.version}, this page ` +
                    `reads ${FORMAT_VERSION}: reload the page`);
  }
  const sections = {};
  for (const [name, [offset, count, dtype]] of
       Object.entries(header.sections)) {
    sections[name] = new ARRAYS[dtype](buffer, offset, count);
  }
  return {header, sections};
}

// Base64 of a gzip file (an exported page's embedded message) -> bytes.
export async function gunzipBase64(text) {
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
  const stream = new Blob([bytes]).stream().pipeThrough(
      new DecompressionStream('gzip'));
  return await new Response(stream).arrayBuffer();
}
