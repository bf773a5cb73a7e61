// three.js reader of the VOXGI_irradiance_volumes glTF extension (docs/gltf_probes.md; usage in
// docs/web_reader.md). A GLTFLoader plugin:
//
//   import { VoxgiIrradianceVolumes } from './voxgi_irradiance_volumes.js';
//   loader.register( ( parser ) => new VoxgiIrradianceVolumes( parser ) );
//   const gltf = await loader.loadAsync( url );
//   gltf.userData.voxgiIrradianceVolumes   // the VoxgiProbeLighting, or undefined
//
// After the scene is built it reads every volume's arrays (accessors and bufferViews), checks
// them (docs/gltf_probes.md "Validation"), packs them into two data textures and patches every
// MeshStandardMaterial (and MeshPhysicalMaterial) of the scene so that its indirect diffuse
// irradiance comes from the probes, by the rules of voxgi_addon/probes/query.py (docs/probes.md
// "Query", docs/gltf_probes.md "Query"): GLSL_QUERY below is that query, step for step. A volume
// whose data is missing, truncated or inconsistent is left out with a console.error naming it
// and the property; the scene still loads and shows with its other lights.
//
// Data textures (texelFetch at linear index i → (i % TEXTURE_WIDTH, i / TEXTURE_WIDTH)):
//   voxgiIndex  RGBA32UI, per volume: its SH index (x: probe at each grid corner), its occlusion
//               index (x: row of each volume) and its rows (texel 8·row + c: corner c's probe,
//               mask low word, mask high word, enabled), 0xFFFFFFFF for none;
//   voxgiProbes RGBA32F, per probe PROBE_TEXELS texels: its 9 SH coefficients (rgb), then its
//               position (xyz) and enabled (w, 1 or 0).
// Both hold exact values (the file's float32 and uint32 numbers), so the shader reads what
// query.py reads.

import {
	DataTexture, FloatType, Matrix3, Matrix4, Mesh, NearestFilter, OrthographicCamera, PlaneGeometry,
	RGBAFormat, RGBAIntegerFormat, Scene, ShaderMaterial, UnsignedIntType, Vector3,
	WebGLRenderTarget, GLSL3,
} from 'three';

export const EXTENSION_NAME = 'VOXGI_irradiance_volumes';
export const NO_INDEX = 0xFFFFFFFF; // voxgi_addon/probes/grid.py NO_INDEX
export const SUBDIVISIONS = 4; // voxgi_addon/probes/placement.py SUBDIVISIONS (4×4×4 mask bits)
export const DISABLED = 2; // flags bit 1 (voxgi_addon/probes/grid.py DISABLED)
export const MAX_VOLUMES = 16; // volumes one shader takes (uniform arrays)
export const TEXTURE_WIDTH = 4096; // texels per row of the two data textures
const MAX_TEXTURE_ROWS = 8192; // rows of the data textures (WebGL2 GPUs give 8192 or more)
const PROBE_TEXELS = 10; // per probe: 9 SH coefficients (RGB), then position (xyz) + enabled (w)

// The extension's arrays (docs/gltf_probes.md "volume"): the float ones are accessors, the
// integer ones bufferViews of tightly packed little-endian uint32 words (glTF allows
// UNSIGNED_INT accessors only for mesh indices). An array whose count is 0 is absent.
const FLOAT = 5126;
const ACCESSOR_FIELDS = [
	// field, accessor type, count from probeCount P (and activeVolumeCount V)
	[ 'positions', 'VEC3', ( P ) => P ],
	[ 'sh', 'VEC3', ( P ) => 9 * P ],
	[ 'validity', 'SCALAR', ( P ) => P ],
];
const WORD_FIELDS = [
	// field, uint32 words from P and V
	[ 'flags', ( P ) => P ],
	[ 'volumeCells', ( P, V ) => V ],
	[ 'volumeProbes', ( P, V ) => 8 * V ],
	[ 'volumeMasks', ( P, V ) => 16 * V ],
];
const COUNT_TEXT = {
	positions: 'probeCount', sh: '9 × probeCount', validity: 'probeCount', flags: 'probeCount',
	volumeCells: 'activeVolumeCount', volumeProbes: '8 × activeVolumeCount',
	volumeMasks: '16 × activeVolumeCount',
};
const ITEM_SIZE = { SCALAR: 1, VEC3: 3 };

/** A volume's data is unusable: names the volume and the field. */
export class VoxgiVolumeError extends Error {

	constructor( label, field, message ) {

		super( `${EXTENSION_NAME}: ${label}: field "${field}": ${message}; this volume is left out ` +
			'(the scene keeps its other lights)' );
		this.name = 'VoxgiVolumeError';
		this.volume = label;
		this.field = field;

	}

}

function isInteger( x ) {

	return typeof x === 'number' && Number.isInteger( x );

}

function isFiniteNumber( x ) {

	return typeof x === 'number' && Number.isFinite( x );

}

/** Flat copy of a loaded accessor's values (handles interleaved and sparse attributes). */
function attributeValues( attribute, Ctor ) {

	const n = attribute.count * attribute.itemSize;
	if ( ! attribute.isInterleavedBufferAttribute && attribute.array instanceof Ctor &&
		attribute.array.length === n ) return attribute.array;
	const out = new Ctor( n );
	for ( let i = 0; i < attribute.count; i ++ ) {

		for ( let c = 0; c < attribute.itemSize; c ++ ) out[ i * attribute.itemSize + c ] = attribute.getComponent( i, c );

	}

	return out;

}

/**
 * Check one volume against docs/gltf_probes.md "Properties", "Binary data" and "Validation" and
 * read its arrays; returns the volume as plain arrays (with its SH and occlusion indices), or
 * throws a VoxgiVolumeError naming the volume and the property.
 */
export async function readVolume( parser, def, index ) {

	let label = `volume ${index}`;
	const fail = ( field, message ) => {

		throw new VoxgiVolumeError( label, field, message );

	};

	if ( def === null || typeof def !== 'object' || Array.isArray( def ) ) fail( '(volume)', 'not a JSON object' );
	if ( def.name !== undefined ) {

		if ( typeof def.name !== 'string' ) fail( 'name', `${JSON.stringify( def.name )} is not a string` );
		label = `volume ${index} "${def.name}"`;

	}

	const json = parser.json;
	const nodes = json.nodes || [];
	if ( def.node === undefined ) fail( 'node', 'missing' );
	if ( ! isInteger( def.node ) || def.node < 0 || def.node >= nodes.length ) {

		fail( 'node', `${JSON.stringify( def.node )} is not the index of a node` );

	}

	const back = ( ( nodes[ def.node ].extensions || {} )[ EXTENSION_NAME ] || {} ).volume;
	if ( back !== index ) fail( 'node', `node ${def.node} does not point back to this volume (its extension names volume ${JSON.stringify( back )})` );

	const vec3 = ( field, check, what ) => {

		const v = def[ field ];
		if ( v === undefined ) fail( field, 'missing' );
		if ( ! Array.isArray( v ) || v.length !== 3 || ! v.every( check ) ) fail( field, `${JSON.stringify( v )} is not 3 ${what}` );
		return v;

	};

	const dims = vec3( 'dims', ( x ) => isInteger( x ) && x >= 1, 'integers ≥ 1' );
	const origin = vec3( 'origin', isFiniteNumber, 'finite numbers' );
	const volumeSize = vec3( 'volumeSize', ( x ) => isFiniteNumber( x ) && x > 0, 'finite numbers > 0' );
	const cornerCount = ( dims[ 0 ] + 1 ) * ( dims[ 1 ] + 1 ) * ( dims[ 2 ] + 1 );
	if ( cornerCount > 2 ** 26 ) fail( 'dims', `${dims.join( ' × ' )} volumes have ${cornerCount} grid corners, more than 2^26` );
	if ( def.subdivisions !== SUBDIVISIONS ) fail( 'subdivisions', `${JSON.stringify( def.subdivisions )}, not ${SUBDIVISIONS}` );
	if ( ! isFiniteNumber( def.maskThreshold ) || def.maskThreshold < 0 || def.maskThreshold > 1 ) {

		fail( 'maskThreshold', `${JSON.stringify( def.maskThreshold )} is not a number in [0, 1]` );

	}

	const P = def.probeCount;
	const V = def.activeVolumeCount;
	const volumeCount = dims[ 0 ] * dims[ 1 ] * dims[ 2 ];
	if ( ! isInteger( P ) || P < 0 ) fail( 'probeCount', `${JSON.stringify( P )} is not an integer ≥ 0` );
	if ( ! isInteger( V ) || V < 0 || V > volumeCount ) fail( 'activeVolumeCount', `${JSON.stringify( V )} is not an integer in [0, ${volumeCount}]` );
	if ( V > 0 && P === 0 ) fail( 'probeCount', `0 probes for ${V} active volumes` );

	const accessors = json.accessors || [];
	const views = json.bufferViews || [];
	const buffers = json.buffers || [];
	const data = {};

	// bytes [start, start + length) of bufferView v must lie in the view and the view in its buffer
	const checkView = async ( field, v, start, length ) => {

		const view = views[ v ];
		if ( view === null || typeof view !== 'object' ) fail( field, `bufferView ${v} does not exist` );
		const buffer = buffers[ view.buffer ];
		if ( buffer === undefined ) fail( field, `bufferView ${v} names buffer ${view.buffer}, which does not exist` );
		const offset = view.byteOffset || 0;
		if ( offset % 4 !== 0 ) fail( field, `bufferView ${v} starts at byte ${offset}, not a multiple of 4` );
		if ( offset + view.byteLength > buffer.byteLength ) fail( field, `bufferView ${v} runs past the end of buffer ${view.buffer} (truncated data)` );
		if ( start + length > view.byteLength ) fail( field, `needs ${start + length} bytes of bufferView ${v}, which has ${view.byteLength} (truncated data)` );
		let bytes;
		try {

			bytes = await parser.getDependency( 'buffer', view.buffer );

		} catch ( error ) {

			fail( field, `buffer ${view.buffer} could not be read (${error && error.message})` );

		}

		if ( bytes.byteLength < buffer.byteLength ) {

			fail( field, `buffer ${view.buffer} holds ${bytes.byteLength} bytes, fewer than its byteLength ${buffer.byteLength} (truncated data)` );

		}

	};

	for ( const [ field, type, countOf ] of ACCESSOR_FIELDS ) {

		const expected = countOf( P, V );
		const a = def[ field ];
		if ( expected === 0 ) {

			if ( a !== undefined ) fail( field, 'present although its count is 0 (it must be absent)' );
			data[ field ] = new Float32Array( 0 );
			continue;

		}

		if ( a === undefined ) fail( field, `missing (required when ${COUNT_TEXT[ field ]} > 0)` );
		if ( ! isInteger( a ) || a < 0 || a >= accessors.length ) fail( field, `${JSON.stringify( a )} is not the index of an accessor` );
		const adef = accessors[ a ];
		if ( adef.type !== type || adef.componentType !== FLOAT ) {

			fail( field, `accessor ${a} is ${adef.type} of component type ${adef.componentType}, expected ${type} of FLOAT (5126)` );

		}

		if ( adef.count !== expected ) fail( field, `accessor ${a} has count ${adef.count}, expected ${COUNT_TEXT[ field ]} = ${expected}` );
		if ( adef.sparse !== undefined ) fail( field, `accessor ${a} is sparse` );
		if ( adef.normalized ) fail( field, `accessor ${a} is normalized` );
		if ( ! isInteger( adef.bufferView ) ) fail( field, `accessor ${a} has no bufferView` );
		const item = ITEM_SIZE[ type ] * 4;
		const view = views[ adef.bufferView ] || {};
		if ( view.byteStride !== undefined && view.byteStride !== item ) fail( field, `bufferView ${adef.bufferView} has byteStride ${view.byteStride} (tightly packed data expected)` );
		const start = adef.byteOffset || 0;
		if ( start % 4 !== 0 ) fail( field, `accessor ${a} starts at byte ${start} of its bufferView, not a multiple of 4` );
		await checkView( field, adef.bufferView, start, expected * item );
		let attribute;
		try {

			attribute = await parser.getDependency( 'accessor', a );

		} catch ( error ) {

			fail( field, `accessor ${a} could not be read (${error && error.message})` );

		}

		const values = attributeValues( attribute, Float32Array );
		if ( attribute.count !== expected || values.length !== expected * ITEM_SIZE[ type ] ) fail( field, `accessor ${a} read as ${attribute.count} items, expected ${expected}` );
		for ( let i = 0; i < values.length; i ++ ) {

			if ( ! Number.isFinite( values[ i ] ) ) fail( field, `value ${i} is ${values[ i ]} (not finite)` );

		}

		data[ field ] = values;

	}

	for ( const [ field, countOf ] of WORD_FIELDS ) {

		const words = countOf( P, V );
		const v = def[ field ];
		if ( words === 0 ) {

			if ( v !== undefined ) fail( field, 'present although its count is 0 (it must be absent)' );
			data[ field ] = new Uint32Array( 0 );
			continue;

		}

		if ( v === undefined ) fail( field, `missing (required when ${COUNT_TEXT[ field ]} > 0)` );
		if ( ! isInteger( v ) || v < 0 || v >= views.length ) fail( field, `${JSON.stringify( v )} is not the index of a bufferView` );
		const view = views[ v ];
		if ( view.byteStride !== undefined ) fail( field, `bufferView ${v} has a byteStride (tightly packed uint32 words expected)` );
		if ( view.byteLength !== 4 * words ) fail( field, `bufferView ${v} has ${view.byteLength} bytes, expected 4 × ${COUNT_TEXT[ field ]} = ${4 * words}` );
		await checkView( field, v, 0, 4 * words );
		let bytes;
		try {

			bytes = await parser.getDependency( 'bufferView', v );

		} catch ( error ) {

			fail( field, `bufferView ${v} could not be read (${error && error.message})` );

		}

		const dv = new DataView( bytes, 0, 4 * words );
		const out = new Uint32Array( words );
		for ( let i = 0; i < words; i ++ ) out[ i ] = dv.getUint32( 4 * i, true ); // little-endian
		data[ field ] = out;

	}

	// contents
	for ( let p = 0; p < P; p ++ ) {

		if ( ! ( data.validity[ p ] >= 0 && data.validity[ p ] <= 1 ) ) fail( 'validity', `probe ${p}: ${data.validity[ p ]} is outside [0, 1]` );
		if ( data.flags[ p ] & ~ 3 ) fail( 'flags', `probe ${p}: ${data.flags[ p ]} has bits other than relocated (1) and disabled (2)` );

	}

	const cells = data.volumeCells;
	for ( let v = 0; v < V; v ++ ) {

		if ( cells[ v ] >= volumeCount ) fail( 'volumeCells', `entry ${v} is volume ${cells[ v ]}, outside the ${dims.join( ' × ' )} grid` );
		if ( v > 0 && cells[ v ] <= cells[ v - 1 ] ) fail( 'volumeCells', `entry ${v} (${cells[ v ]}) does not follow ${cells[ v - 1 ]} in strictly ascending order` );

	}

	const probes = data.volumeProbes;
	for ( let i = 0; i < probes.length; i ++ ) {

		if ( probes[ i ] >= P ) fail( 'volumeProbes', `entry ${i} is probe ${probes[ i ]}, but probeCount is ${P}` );

	}

	const volume = {
		index, label, name: def.name || '', node: def.node,
		dims, origin, volumeSize, probeCount: P, activeVolumeCount: V,
		maskThreshold: def.maskThreshold,
		positions: data.positions, sh: data.sh, flags: data.flags, validity: data.validity,
		volumeCells: cells, volumeProbes: probes, volumeMasks: data.volumeMasks,
	};
	Object.assign( volume, indexArrays( volume, ( message ) => fail( 'volumeProbes', message ) ) );
	return volume;

}

/**
 * Bowald's SH index ((X+1)(Y+1)(Z+1) grid corners → probe) and occlusion index (X·Y·Z volumes →
 * row of volumeCells), 0xFFFFFFFF where none, as voxgi_addon/probes/grid.py index_arrays builds
 * them. `conflict(message)` is called where two volumes name different probes at one grid
 * corner, or one probe sits at two corners (docs/gltf_probes.md "Validation").
 */
export function indexArrays( volume, conflict = () => {} ) {

	const [ X, Y, Z ] = volume.dims;
	const maskIndex = new Uint32Array( X * Y * Z ).fill( NO_INDEX );
	const shIndex = new Uint32Array( ( X + 1 ) * ( Y + 1 ) * ( Z + 1 ) ).fill( NO_INDEX );
	const cornerOf = new Map();
	const cells = volume.volumeCells;
	for ( let v = 0; v < cells.length; v ++ ) {

		const cell = cells[ v ];
		maskIndex[ cell ] = v;
		const x = cell % X, y = Math.floor( cell / X ) % Y, z = Math.floor( cell / ( X * Y ) );
		for ( let c = 0; c < 8; c ++ ) {

			const corner = ( x + ( c & 1 ) ) + ( X + 1 ) * ( ( y + ( ( c >> 1 ) & 1 ) ) + ( Y + 1 ) * ( z + ( ( c >> 2 ) & 1 ) ) );
			const probe = volume.volumeProbes[ 8 * v + c ];
			if ( shIndex[ corner ] !== NO_INDEX && shIndex[ corner ] !== probe ) {

				conflict( `grid corner ${corner} is probe ${shIndex[ corner ]} for one volume and probe ${probe} for active volume ${v}` );

			}

			if ( cornerOf.has( probe ) && cornerOf.get( probe ) !== corner ) {

				conflict( `probe ${probe} sits at grid corners ${cornerOf.get( probe )} and ${corner}` );

			}

			cornerOf.set( probe, corner );
			shIndex[ corner ] = probe;

		}

	}

	return { shIndex, maskIndex };

}

// The query, in GLSL ES 3.00: voxgi_addon/probes/query.py probe_weights + query_irradiance +
// query_grids, step for step (docs/probes.md "Query"). Needs three's <common> (PI) before it.
export const GLSL_QUERY = /* glsl */`
uniform highp usampler2D voxgiIndex; // RGBA32UI: SH index, occlusion index, corner rows
uniform highp sampler2D voxgiProbes; // RGBA32F: per probe 9 SH texels (rgb) + position, enabled
uniform mat4 voxgiInverseWorld[ VOXGI_VOLUMES ]; // world → grid frame (volume node's inverse)
uniform mat3 voxgiNormalToGrid[ VOXGI_VOLUMES ]; // its inverse transpose, for normals
uniform vec3 voxgiOrigin[ VOXGI_VOLUMES ];
uniform vec3 voxgiVolumeSize[ VOXGI_VOLUMES ];
uniform ivec3 voxgiDims[ VOXGI_VOLUMES ];
uniform ivec4 voxgiOffsets[ VOXGI_VOLUMES ]; // texels: SH index, occlusion index, corner rows, probes

const uint VOXGI_NO_INDEX = 0xFFFFFFFFu;

uvec4 voxgiFetchIndex( int i ) {

	return texelFetch( voxgiIndex, ivec2( i % VOXGI_TEXTURE_WIDTH, i / VOXGI_TEXTURE_WIDTH ), 0 );

}

vec4 voxgiFetchProbe( int i ) {

	return texelFetch( voxgiProbes, ivec2( i % VOXGI_TEXTURE_WIDTH, i / VOXGI_TEXTURE_WIDTH ), 0 );

}

// Irradiance ∫ L cos dω at grid-frame point p with unit grid-frame normal n from volume v.
vec3 voxgiVolumeIrradiance( const in int v, const in vec3 p, const in vec3 n ) {

	ivec3 dims = voxgiDims[ v ];
	ivec4 offsets = voxgiOffsets[ v ];
	vec3 g = ( p - voxgiOrigin[ v ] ) / voxgiVolumeSize[ v ];
	vec3 cellf = clamp( floor( g ), vec3( 0.0 ), vec3( dims - 1 ) );
	ivec3 cell = ivec3( cellf );
	vec3 f = clamp( g - cellf, 0.0, 1.0 );

	// occlusion index → this volume's row; the point's sub-volume → its mask bit
	int volume = cell.x + dims.x * ( cell.y + dims.y * cell.z );
	uint row = voxgiFetchIndex( offsets.y + volume ).x;
	bool hasRow = row != VOXGI_NO_INDEX; // an active volume
	ivec3 sub = clamp( ivec3( floor( f * float( VOXGI_SUBDIVISIONS ) ) ), ivec3( 0 ), ivec3( VOXGI_SUBDIVISIONS - 1 ) );
	int bit = sub.x + VOXGI_SUBDIVISIONS * ( sub.y + VOXGI_SUBDIVISIONS * sub.z );

	int probe[ 8 ]; // first texel of each corner's probe
	float usable[ 8 ]; // trilinear weight × enabled
	float weight[ 8 ];
	float total = 0.0;
	for ( int c = 0; c < 8; c ++ ) {

		ivec3 o = ivec3( c & 1, ( c >> 1 ) & 1, ( c >> 2 ) & 1 );
		uint index;
		bool enabled, seen;
		if ( hasRow ) {

			// an active volume's row holds its corner probes (the SH index's, validated equal),
			// their enabled flags and masks: one fetch per corner
			uvec4 r = voxgiFetchIndex( offsets.z + 8 * int( row ) + c );
			index = r.x;
			enabled = r.w != 0u;
			seen = ( ( ( bit < 32 ? r.y : r.z ) >> uint( bit & 31 ) ) & 1u ) != 0u;

		} else {

			// an inactive volume: the SH index, no masks
			ivec3 corner = cell + o;
			index = voxgiFetchIndex( offsets.x + corner.x + ( dims.x + 1 ) * ( corner.y + ( dims.y + 1 ) * corner.z ) ).x;
			enabled = index != VOXGI_NO_INDEX && voxgiFetchProbe( ( offsets.w + int( index ) ) * ${PROBE_TEXELS} + 9 ).w > 0.5;
			seen = true;

		}

		probe[ c ] = ( offsets.w + ( index != VOXGI_NO_INDEX ? int( index ) : 0 ) ) * ${PROBE_TEXELS};
		vec3 tri = mix( 1.0 - f, f, vec3( o ) ); // trilinear: f where the corner's offset is 1
		usable[ c ] = enabled ? tri.x * tri.y * tri.z : 0.0;
		weight[ c ] = seen ? usable[ c ] : 0.0;
		total += weight[ c ];

	}

	if ( total <= 0.0 ) { // no corner probe sees the sub-volume: probes in front of the surface

		total = 0.0;
		for ( int c = 0; c < 8; c ++ ) {

			weight[ c ] = usable[ c ] > 0.0 && dot( voxgiFetchProbe( probe[ c ] + 9 ).xyz - p, n ) > 0.0 ? usable[ c ] : 0.0;
			total += weight[ c ];

		}

	}

	if ( total <= 0.0 ) { // failing those, every enabled corner probe

		total = 0.0;
		for ( int c = 0; c < 8; c ++ ) {

			weight[ c ] = usable[ c ];
			total += weight[ c ];

		}

	}

	if ( total <= 0.0 ) return vec3( 0.0 );

	// the clamped-cosine convolution of the blended coefficients (voxgi_addon/probes/sh.py:
	// Sloan's order, Â = π, 2π/3, π/4)
	float basis[ 9 ];
	basis[ 0 ] = 0.28209479177387814 * PI;
	basis[ 1 ] = 0.4886025119029199 * n.y * ( 2.0 * PI / 3.0 );
	basis[ 2 ] = 0.4886025119029199 * n.z * ( 2.0 * PI / 3.0 );
	basis[ 3 ] = 0.4886025119029199 * n.x * ( 2.0 * PI / 3.0 );
	basis[ 4 ] = 1.0925484305920792 * n.x * n.y * ( PI / 4.0 );
	basis[ 5 ] = 1.0925484305920792 * n.y * n.z * ( PI / 4.0 );
	basis[ 6 ] = 0.31539156525252005 * ( 3.0 * n.z * n.z - 1.0 ) * ( PI / 4.0 );
	basis[ 7 ] = 1.0925484305920792 * n.x * n.z * ( PI / 4.0 );
	basis[ 8 ] = 0.5462742152960396 * ( n.x * n.x - n.y * n.y ) * ( PI / 4.0 );
	// blend the coefficients of the corners that count (a weight of 0 adds nothing: skipped)
	vec3 blended[ 9 ];
	for ( int k = 0; k < 9; k ++ ) blended[ k ] = vec3( 0.0 );
	for ( int c = 0; c < 8; c ++ ) {

		if ( weight[ c ] <= 0.0 ) continue;
		float w = weight[ c ] / total;
		int base = probe[ c ];
		for ( int k = 0; k < 9; k ++ ) blended[ k ] += w * voxgiFetchProbe( base + k ).rgb;

	}

	vec3 e = vec3( 0.0 );
	for ( int k = 0; k < 9; k ++ ) e += basis[ k ] * blended[ k ];
	return max( e, vec3( 0.0 ) );

}

// query_grids: the first volume whose box holds the point, else the first volume (clamped).
vec3 voxgiIrradianceAt( const in vec3 worldPosition, const in vec3 worldNormal ) {

	int chosen = 0;
	for ( int v = VOXGI_VOLUMES - 1; v >= 0; v -- ) {

		vec3 p = ( voxgiInverseWorld[ v ] * vec4( worldPosition, 1.0 ) ).xyz;
		vec3 lo = voxgiOrigin[ v ];
		vec3 hi = lo + vec3( voxgiDims[ v ] ) * voxgiVolumeSize[ v ];
		if ( all( greaterThanEqual( p, lo ) ) && all( lessThanEqual( p, hi ) ) ) chosen = v;

	}

	vec3 p = ( voxgiInverseWorld[ chosen ] * vec4( worldPosition, 1.0 ) ).xyz;
	vec3 n = normalize( voxgiNormalToGrid[ chosen ] * worldNormal );
	return voxgiVolumeIrradiance( chosen, p, n );

}
`;

// what the patched MeshStandardMaterial's shaders get (onBeforeCompile)
const VERTEX_DECLARATIONS = 'varying vec3 vVoxgiWorldPosition;\n';
const VERTEX_WORLD_POSITION = /* glsl */`
	{
		vec4 voxgiPosition = vec4( transformed, 1.0 );
		#ifdef USE_BATCHING
			voxgiPosition = batchingMatrix * voxgiPosition;
		#endif
		#ifdef USE_INSTANCING
			voxgiPosition = instanceMatrix * voxgiPosition;
		#endif
		vVoxgiWorldPosition = ( modelMatrix * voxgiPosition ).xyz;
	}
`;
const FRAGMENT_DECLARATIONS = /* glsl */`
varying vec3 vVoxgiWorldPosition;
uniform int voxgiDebug; // 0 lit; 1 irradiance / π (Diffuse Indirect); 2 world position; 3 world normal
vec3 voxgiIrradiance = vec3( 0.0 );
vec3 voxgiWorldNormal = vec3( 0.0, 0.0, 1.0 );
`;
// after <lights_fragment_maps>: the probes' irradiance replaces the indirect diffuse irradiance
// (ambient, hemisphere, light probes, light map) that RE_IndirectDiffuse would use
const FRAGMENT_REPLACE_IRRADIANCE = /* glsl */`
#if defined( RE_IndirectDiffuse )
	voxgiWorldNormal = inverseTransformDirection( geometryNormal, viewMatrix );
	voxgiIrradiance = voxgiIrradianceAt( vVoxgiWorldPosition, voxgiWorldNormal );
	irradiance = voxgiIrradiance;
#endif
`;
const FRAGMENT_DEBUG = /* glsl */`
	if ( voxgiDebug == 1 ) gl_FragColor = vec4( voxgiIrradiance * RECIPROCAL_PI, 1.0 );
	else if ( voxgiDebug == 2 ) gl_FragColor = vec4( vVoxgiWorldPosition, 1.0 );
	else if ( voxgiDebug == 3 ) gl_FragColor = vec4( voxgiWorldNormal, 1.0 );
`;

export const DEBUG_MODES = { lit: 0, 'diffuse-indirect': 1, position: 2, normal: 3 };

function replaceOnce( source, anchor, replacement, what ) {

	if ( ! source.includes( anchor ) ) throw new Error( `${EXTENSION_NAME}: ${what} has no ${anchor} to patch` );
	return source.replace( anchor, replacement );

}

/** The probe lighting of a loaded scene: data textures, uniforms, patched materials. */
export class VoxgiProbeLighting {

	constructor( volumes ) {

		if ( volumes.length < 1 || volumes.length > MAX_VOLUMES ) throw new Error( `${EXTENSION_NAME}: ${volumes.length} volumes (1–${MAX_VOLUMES} supported)` );
		this.volumes = volumes; // each: readVolume's result + .object (the node's Object3D)
		this.materials = new Set();
		this.debugMode = 0;

		// texel layout (see the top of this file): per volume its SH index, occlusion index and
		// rows in voxgiIndex, its probes in voxgiProbes (PROBE_TEXELS each)
		let indexTexels = 0, probeCount = 0;
		// (readVolume built each volume's shIndex and maskIndex)
		const offsets = [];
		volumes.forEach( ( volume, i ) => {

			const o = [ indexTexels, 0, 0, probeCount ];
			indexTexels += volumes[ i ].shIndex.length;
			o[ 1 ] = indexTexels;
			indexTexels += volumes[ i ].maskIndex.length;
			o[ 2 ] = indexTexels;
			indexTexels += volume.volumeMasks.length / 2;
			probeCount += volume.probeCount;
			offsets.push( o );

		} );
		const probeTexels = Math.max( 1, probeCount * PROBE_TEXELS );
		const indexHeight = Math.max( 1, Math.ceil( indexTexels / TEXTURE_WIDTH ) );
		const probeHeight = Math.max( 1, Math.ceil( probeTexels / TEXTURE_WIDTH ) );
		if ( Math.max( indexHeight, probeHeight ) > MAX_TEXTURE_ROWS ) {

			throw new Error( `the volumes need data textures of ${TEXTURE_WIDTH} × ${Math.max( indexHeight, probeHeight )} texels, more than this reader's ${TEXTURE_WIDTH} × ${MAX_TEXTURE_ROWS}` );

		}

		const index = new Uint32Array( TEXTURE_WIDTH * indexHeight * 4 );
		const probes = new Float32Array( TEXTURE_WIDTH * probeHeight * 4 );
		volumes.forEach( ( volume, i ) => {

			const [ shAt, maskIndexAt, rowsAt, probeAt ] = offsets[ i ];
			volumes[ i ].shIndex.forEach( ( value, k ) => {

				index[ 4 * ( shAt + k ) ] = value;

			} );
			volumes[ i ].maskIndex.forEach( ( value, k ) => {

				index[ 4 * ( maskIndexAt + k ) ] = value;

			} );
			// row texel 8v + c: (probe, mask low word, mask high word, enabled)
			for ( let k = 0; k < volume.volumeProbes.length; k ++ ) {

				const probe = volume.volumeProbes[ k ];
				index[ 4 * ( rowsAt + k ) ] = probe;
				index[ 4 * ( rowsAt + k ) + 1 ] = volume.volumeMasks[ 2 * k ];
				index[ 4 * ( rowsAt + k ) + 2 ] = volume.volumeMasks[ 2 * k + 1 ];
				index[ 4 * ( rowsAt + k ) + 3 ] = ( volume.flags[ probe ] & DISABLED ) === 0 ? 1 : 0;

			}

			for ( let p = 0; p < volume.probeCount; p ++ ) {

				const base = ( probeAt + p ) * PROBE_TEXELS * 4;
				for ( let k = 0; k < 9; k ++ ) {

					for ( let c = 0; c < 3; c ++ ) probes[ base + 4 * k + c ] = volume.sh[ 3 * ( 9 * p + k ) + c ];

				}

				for ( let c = 0; c < 3; c ++ ) probes[ base + 36 + c ] = volume.positions[ 3 * p + c ];
				probes[ base + 39 ] = ( volume.flags[ p ] & DISABLED ) === 0 ? 1.0 : 0.0;

			}

		} );
		this.textureHeights = [ indexHeight, probeHeight ];

		this.indexTexture = new DataTexture( index, TEXTURE_WIDTH, indexHeight, RGBAIntegerFormat, UnsignedIntType );
		this.indexTexture.internalFormat = 'RGBA32UI';
		this.probeTexture = new DataTexture( probes, TEXTURE_WIDTH, probeHeight, RGBAFormat, FloatType );
		for ( const texture of [ this.indexTexture, this.probeTexture ] ) {

			texture.minFilter = texture.magFilter = NearestFilter;
			texture.generateMipmaps = false;
			texture.flipY = false;
			texture.needsUpdate = true;

		}

		this.uniforms = {
			voxgiIndex: { value: this.indexTexture },
			voxgiProbes: { value: this.probeTexture },
			voxgiInverseWorld: { value: volumes.map( () => new Matrix4() ) },
			voxgiNormalToGrid: { value: volumes.map( () => new Matrix3() ) },
			voxgiOrigin: { value: volumes.map( ( v ) => new Vector3().fromArray( v.origin ) ) },
			voxgiVolumeSize: { value: volumes.map( ( v ) => new Vector3().fromArray( v.volumeSize ) ) },
			voxgiDims: { value: volumes.flatMap( ( v ) => v.dims ) },
			voxgiOffsets: { value: offsets.flat() },
			voxgiDebug: { value: 0 },
		};
		this.defines = {
			VOXGI_VOLUMES: volumes.length,
			VOXGI_TEXTURE_WIDTH: TEXTURE_WIDTH,
			VOXGI_SUBDIVISIONS: SUBDIVISIONS,
		};
		this.cacheKey = `voxgi:${volumes.length}`;
		this.update();

	}

	/** The volume nodes' inverse world matrices (call after they move; patched meshes do it before each draw). */
	update() {

		this.volumes.forEach( ( volume, i ) => {

			const world = volume.object.matrixWorld;
			this.uniforms.voxgiInverseWorld.value[ i ].copy( world ).invert();
			// normals: the inverse transpose of the inverse, i.e. the transpose (docs/gltf_probes.md "Extending Nodes")
			this.uniforms.voxgiNormalToGrid.value[ i ].setFromMatrix4( world ).transpose();

		} );

	}

	/** 'lit' (default), 'diffuse-indirect' (irradiance / π, linear), 'position', 'normal'. */
	setDebugMode( mode ) {

		if ( ! ( mode in DEBUG_MODES ) ) throw new Error( `${EXTENSION_NAME}: unknown debug mode ${mode}` );
		this.debugMode = DEBUG_MODES[ mode ];
		this.uniforms.voxgiDebug.value = this.debugMode;

	}

	/** Patch one material (MeshStandardMaterial or MeshPhysicalMaterial); false for others. */
	patchMaterial( material ) {

		if ( ! material || ! material.isMeshStandardMaterial ) return false;
		if ( this.materials.has( material ) ) return true;
		const lighting = this;
		const previousCompile = material.onBeforeCompile;
		const previousKey = material.customProgramCacheKey;
		material.onBeforeCompile = function ( shader, renderer ) {

			previousCompile.call( this, shader, renderer );
			lighting.patchShader( shader );

		};

		material.customProgramCacheKey = function () {

			return previousKey.call( this ) + '|' + lighting.cacheKey;

		};

		material.userData.voxgiProbeLit = true;
		material.userData.voxgiPrevious = { onBeforeCompile: previousCompile, customProgramCacheKey: previousKey };
		material.needsUpdate = true;
		this.materials.add( material );
		return true;

	}

	patchShader( shader ) {

		Object.assign( shader.uniforms, this.uniforms ); // shared objects: one update reaches all
		shader.defines = Object.assign( shader.defines || {}, this.defines );
		shader.vertexShader = replaceOnce( shader.vertexShader, '#include <common>', '#include <common>\n' + VERTEX_DECLARATIONS, 'the vertex shader' );
		shader.vertexShader = replaceOnce( shader.vertexShader, '#include <project_vertex>', '#include <project_vertex>\n' + VERTEX_WORLD_POSITION, 'the vertex shader' );
		shader.fragmentShader = replaceOnce( shader.fragmentShader, '#include <common>', '#include <common>\n' + FRAGMENT_DECLARATIONS + GLSL_QUERY, 'the fragment shader' );
		shader.fragmentShader = replaceOnce( shader.fragmentShader, '#include <lights_fragment_maps>', '#include <lights_fragment_maps>\n' + FRAGMENT_REPLACE_IRRADIANCE, 'the fragment shader' );
		shader.fragmentShader = replaceOnce( shader.fragmentShader, '#include <dithering_fragment>', '#include <dithering_fragment>\n' + FRAGMENT_DEBUG, 'the fragment shader' );

	}

	/** Undo patchMaterial on every patched material (they go back to three's own lighting). */
	remove() {

		for ( const material of this.materials ) {

			material.onBeforeCompile = material.userData.voxgiPrevious.onBeforeCompile;
			material.customProgramCacheKey = material.userData.voxgiPrevious.customProgramCacheKey;
			delete material.userData.voxgiPrevious;
			delete material.userData.voxgiProbeLit;
			material.needsUpdate = true;

		}

		this.materials.clear();

	}

	/** Patch every MeshStandardMaterial under root; returns how many meshes are probe-lit. */
	apply( root ) {

		let meshes = 0;
		root.traverse( ( object ) => {

			if ( ! object.isMesh ) return;
			const materials = Array.isArray( object.material ) ? object.material : [ object.material ];
			let lit = false;
			for ( const material of materials ) lit = this.patchMaterial( material ) || lit;
			if ( ! lit ) return;
			meshes ++;
			const previous = object.onBeforeRender;
			object.onBeforeRender = ( ...args ) => {

				this.update();
				previous.apply( object, args );

			};

		} );
		return meshes;

	}

	/**
	 * Evaluate the shader's query (voxgiIrradianceAt, the GLSL above) at world points with world
	 * normals, by drawing one fragment per point into a float render target: the same code the
	 * materials run, for checking it against voxgi_addon/probes/query.py. Returns Float32Array
	 * (N × 3) irradiance.
	 */
	evaluate( renderer, points, normals ) {

		const n = points.length / 3;
		const width = Math.min( n, 1024 ), height = Math.max( 1, Math.ceil( n / 1024 ) );
		const pack = ( values ) => {

			const data = new Float32Array( width * height * 4 );
			for ( let i = 0; i < n; i ++ ) for ( let c = 0; c < 3; c ++ ) data[ 4 * i + c ] = values[ 3 * i + c ];
			const texture = new DataTexture( data, width, height, RGBAFormat, FloatType );
			texture.minFilter = texture.magFilter = NearestFilter;
			texture.needsUpdate = true;
			return texture;

		};

		const pointTexture = pack( points ), normalTexture = pack( normals );
		const material = new ShaderMaterial( {
			glslVersion: GLSL3,
			defines: { ...this.defines },
			uniforms: { ...this.uniforms, voxgiPoints: { value: pointTexture }, voxgiNormals: { value: normalTexture } },
			vertexShader: 'void main() { gl_Position = vec4( position.xy * 2.0, 0.0, 1.0 ); }',
			fragmentShader: '#include <common>\n' + GLSL_QUERY + /* glsl */`
				uniform highp sampler2D voxgiPoints;
				uniform highp sampler2D voxgiNormals;
				out highp vec4 voxgiOut;
				void main() {
					ivec2 at = ivec2( gl_FragCoord.xy );
					vec3 p = texelFetch( voxgiPoints, at, 0 ).xyz;
					vec3 nrm = texelFetch( voxgiNormals, at, 0 ).xyz;
					voxgiOut = vec4( voxgiIrradianceAt( p, nrm ), 1.0 );
				}`,
		} );
		const target = new WebGLRenderTarget( width, height, { type: FloatType, format: RGBAFormat, depthBuffer: false } );
		const scene = new Scene();
		const quad = new Mesh( new PlaneGeometry( 1, 1 ), material );
		quad.frustumCulled = false;
		scene.add( quad );
		this.update();
		const previousTarget = renderer.getRenderTarget();
		renderer.setRenderTarget( target );
		renderer.render( scene, new OrthographicCamera() );
		const pixels = new Float32Array( width * height * 4 );
		renderer.readRenderTargetPixels( target, 0, 0, width, height, pixels );
		renderer.setRenderTarget( previousTarget );
		const out = new Float32Array( n * 3 );
		for ( let i = 0; i < n; i ++ ) for ( let c = 0; c < 3; c ++ ) out[ 3 * i + c ] = pixels[ 4 * i + c ];
		target.dispose();
		material.dispose();
		quad.geometry.dispose();
		pointTexture.dispose();
		normalTexture.dispose();
		return out;

	}

	dispose() {

		this.indexTexture.dispose();
		this.probeTexture.dispose();

	}

}

/** The GLTFLoader plugin. */
export class VoxgiIrradianceVolumes {

	constructor( parser ) {

		this.parser = parser;
		this.name = EXTENSION_NAME;

	}

	// after the scene is built; never rejects: a broken extension must not break the load
	async afterRoot( result ) {

		try {

			await this._afterRoot( result );

		} catch ( error ) {

			console.error( `${EXTENSION_NAME}: the probes are not used: ${error && error.message}` );

		}

	}

	async _afterRoot( result ) {

		const parser = this.parser;
		const root = ( parser.json.extensions || {} )[ EXTENSION_NAME ];
		if ( root === undefined ) return;
		const report = { volumes: [], errors: [], lighting: null };
		result.userData.voxgiIrradianceVolumesReport = report;
		const fail = ( message ) => {

			report.errors.push( message );
			console.error( message );

		};

		if ( root === null || ! Array.isArray( root.volumes ) ) {

			fail( `${EXTENSION_NAME}: field "volumes": not an array; the probes are not used (the scene keeps its other lights)` );
			return;

		}

		result.scene.updateMatrixWorld( true );
		const volumes = [];
		for ( let i = 0; i < root.volumes.length; i ++ ) {

			try {

				const volume = await readVolume( parser, root.volumes[ i ], i );
				volume.object = await this._nodeObject( volume.node, result.scene );
				if ( ! volume.object ) {

					// docs/gltf_probes.md: a volume belongs to the scene its node is in
					console.info( `${EXTENSION_NAME}: ${volume.label} belongs to another scene than the one shown` );
					continue;

				}

				if ( volumes.length === MAX_VOLUMES ) throw new VoxgiVolumeError( volume.label, '(volume)', `more than ${MAX_VOLUMES} volumes` );
				volumes.push( volume );

			} catch ( error ) {

				fail( error instanceof VoxgiVolumeError ? error.message
					: `${EXTENSION_NAME}: volume ${i}: ${error && error.message}; this volume is left out (the scene keeps its other lights)` );

			}

		}

		report.volumes = volumes.map( ( v ) => v.label );
		if ( volumes.length === 0 ) return;
		const lighting = new VoxgiProbeLighting( volumes );
		lighting.errors = report.errors;
		report.lighting = lighting;
		report.probeLitMeshes = lighting.apply( result.scene );
		result.userData.voxgiIrradianceVolumes = lighting;

	}

	// the Object3D of a node in the loaded scene (GLTFLoader's node cache; a node that the
	// scene holds as a clone is found through the parser's associations)
	async _nodeObject( nodeIndex, scene ) {

		const object = await this.parser.getDependency( 'node', nodeIndex );
		let inScene = false;
		for ( let o = object; o; o = o.parent ) if ( o === scene ) inScene = true;
		if ( inScene ) return object;
		let found = null;
		scene.traverse( ( o ) => {

			const association = this.parser.associations.get( o );
			if ( found === null && association && association.nodes === nodeIndex ) found = o;

		} );
		return found;

	}

}
