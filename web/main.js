// The minimal page of docs/web_reader.md: loads ?file=URL.glb with GLTFLoader and the
// VOXGI_irradiance_volumes plugin, shows it from the file's first camera (or one that frames the
// scene), and exposes window.voxgi for the browser tests (tests/web) and the benchmark
// (tools/bench/bench_web_probes.py).
//
// URL parameters: file (required), debug = lit | diffuse-indirect | position | normal (what the
// probe-lit materials output; diffuse-indirect is irradiance / π, linear), width / height (the
// drawing size, default the window's), probes=off (load without the plugin), lights =
// blender (default) | photometric: Blender's exporter writes punctual lights in photometric
// units (candela, lux: W × 683 / 4π), the probes hold Blender's radiometric units; 'blender'
// divides the lights by 683 (as Blender's importer does) so both are in one unit and the page
// looks like Blender's render; shadows=off (default on: every light casts shadows, as in Blender).

import {
	Box3, FloatType, HemisphereLight, Matrix3, PerspectiveCamera, RGBAFormat, Vector3, WebGLRenderer,
	WebGLRenderTarget, NoToneMapping,
} from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { VoxgiIrradianceVolumes } from './voxgi_irradiance_volumes.js';

const WATTS_TO_LUMENS = 683; // Blender's glTF exporter and importer (PBR_WATTS_TO_LUMENS)
const params = new URLSearchParams( location.search );
const status = document.getElementById( 'status' );
const app = window.voxgi = {
	state: 'loading', // 'loading' → 'ready' | 'error'
	error: null,
	timings: { start: performance.now() }, // ms since navigation start
	probeErrors: [],
};

function base64( floats ) {

	const bytes = new Uint8Array( floats.buffer, floats.byteOffset, floats.byteLength );
	let text = '';
	for ( let i = 0; i < bytes.length; i += 0x8000 ) text += String.fromCharCode.apply( null, bytes.subarray( i, i + 0x8000 ) );
	return btoa( text );

}

function fail( error ) {

	app.state = 'error';
	app.error = String( error && error.message || error );
	status.textContent = `error: ${app.error}`;
	console.error( `voxgi page: ${app.error}` );

}

async function main() {

	const file = params.get( 'file' );
	if ( ! file ) throw new Error( 'no ?file=URL.glb given' );
	const width = Number( params.get( 'width' ) ) || window.innerWidth;
	const height = Number( params.get( 'height' ) ) || window.innerHeight;
	const debug = params.get( 'debug' ) || 'lit';

	const renderer = new WebGLRenderer( { antialias: debug === 'lit', preserveDrawingBuffer: true } );
	renderer.setPixelRatio( 1 );
	renderer.setSize( width, height );
	renderer.toneMapping = NoToneMapping;
	const shaderErrors = app.shaderErrors = [];
	renderer.debug.onShaderError = ( gl, program, vertexShader, fragmentShader ) => {

		const log = [ gl.getProgramInfoLog( program ), gl.getShaderInfoLog( vertexShader ), gl.getShaderInfoLog( fragmentShader ) ].join( '\n' ).trim();
		shaderErrors.push( log );
		console.error( `voxgi page: a shader failed to compile: ${log.slice( 0, 2000 )}` );

	};
	document.body.appendChild( renderer.domElement );

	const loader = new GLTFLoader();
	if ( params.get( 'probes' ) !== 'off' ) loader.register( ( parser ) => new VoxgiIrradianceVolumes( parser ) );
	const gltf = await loader.loadAsync( file );
	app.timings.loaded = performance.now();
	const scene = gltf.scene;
	const lighting = gltf.userData.voxgiIrradianceVolumes || null;
	const report = gltf.userData.voxgiIrradianceVolumesReport;
	app.probeErrors = report ? report.errors : [];

	// a file with no lights of its own (or whose probes could not be used) is not shown black:
	// a dim sky light, which probe-lit materials ignore (the probes replace indirect diffuse)
	let hasLight = false;
	const lightScale = params.get( 'lights' ) === 'photometric' ? 1 : 1 / WATTS_TO_LUMENS;
	const shadows = params.get( 'shadows' ) !== 'off';
	renderer.shadowMap.enabled = shadows;
	scene.traverse( ( o ) => {

		if ( o.isMesh ) o.castShadow = o.receiveShadow = shadows;
		if ( ! o.isLight ) return;
		hasLight = true;
		o.intensity *= lightScale;
		if ( shadows && o.shadow ) {

			o.castShadow = true;
			o.shadow.mapSize.set( 1024, 1024 );
			o.shadow.bias = - 0.001;
			o.shadow.normalBias = 0.02;

		}

	} );
	if ( ! hasLight ) scene.add( new HemisphereLight( 0xffffff, 0x404040, 1.0 ) );

	let camera = gltf.cameras.length ? gltf.cameras[ 0 ] : null;
	if ( camera && camera.isPerspectiveCamera ) {

		camera.aspect = width / height;
		camera.updateProjectionMatrix();

	} else if ( ! camera ) {

		const box = new Box3().setFromObject( scene );
		const size = box.getSize( new Vector3() ).length() || 1;
		const center = box.getCenter( new Vector3() );
		camera = new PerspectiveCamera( 50, width / height, size / 100, size * 10 );
		camera.position.copy( center ).add( new Vector3( 0.3, 0.4, 1.0 ).normalize().multiplyScalar( size * 1.2 ) );
		camera.lookAt( center );

	}

	if ( lighting ) lighting.setDebugMode( debug );
	scene.updateMatrixWorld( true );
	renderer.render( scene, camera );
	if ( lighting && shaderErrors.length ) {

		// never a black scene: without the probe shaders, three's own lighting
		const message = `${lighting.volumes.length} VOXGI_irradiance_volumes volume(s) not used: the probe shader failed to compile`;
		console.error( `voxgi page: ${message}` );
		app.probeErrors.push( message );
		lighting.remove();
		renderer.render( scene, camera );

	}
	const gl = renderer.getContext();
	gl.readPixels( 0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array( 4 ) ); // wait for the frame
	app.timings.firstFrame = performance.now();

	Object.assign( app, { renderer, scene, camera, lighting, gltf, width, height } );

	// the linear output of one debug mode, rendered into a float target: {width, height,
	// data: base64 Float32 RGBA, rows bottom to top}; alpha 1 where a probe-lit surface is seen
	app.readPass = ( mode ) => {

		if ( ! lighting ) throw new Error( 'the scene has no usable VOXGI_irradiance_volumes' );
		const target = new WebGLRenderTarget( width, height, { type: FloatType, format: RGBAFormat } );
		const background = scene.background;
		scene.background = null;
		lighting.setDebugMode( mode );
		renderer.setRenderTarget( target );
		renderer.setClearColor( 0x000000, 0 );
		renderer.clear();
		renderer.render( scene, camera );
		const pixels = new Float32Array( width * height * 4 );
		renderer.readRenderTargetPixels( target, 0, 0, width, height, pixels );
		renderer.setRenderTarget( null );
		lighting.setDebugMode( debug );
		scene.background = background;
		target.dispose();
		return { width, height, data: base64( pixels ) };

	};

	// the shader's query at points given in volume `volume`'s grid frame (mapped to the world by
	// its node's matrixWorld here, in float64) with unit normals: base64 Float32 (N × 3)
	app.evaluateInFrame = ( volume, points, normals ) => {

		const node = lighting.volumes[ volume ].object;
		const world = new Float32Array( points.length ), worldNormals = new Float32Array( normals.length );
		const v = new Vector3();
		const normalMatrix = new Matrix3().getNormalMatrix( node.matrixWorld );
		for ( let i = 0; i < points.length; i += 3 ) {

			v.fromArray( points, i ).applyMatrix4( node.matrixWorld ).toArray( world, i );
			v.fromArray( normals, i ).applyMatrix3( normalMatrix ).normalize().toArray( worldNormals, i );

		}

		return base64( lighting.evaluate( renderer, world, worldNormals ) );

	};

	// mean RGB (0–255) of the canvas as shown (lit mode): the bad-input tests' "not black"
	app.readCanvas = () => {

		renderer.render( scene, camera );
		const pixels = new Uint8Array( width * height * 4 );
		gl.readPixels( 0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, pixels );
		const mean = [ 0, 0, 0 ];
		for ( let i = 0; i < pixels.length; i += 4 ) for ( let c = 0; c < 3; c ++ ) mean[ c ] += pixels[ i + c ] / ( width * height );
		return mean;

	};

	status.textContent = app.probeErrors.length ? `probes not used: ${app.probeErrors.join( '\n' )}` : '';
	app.state = 'ready';

}

main().catch( fail );
