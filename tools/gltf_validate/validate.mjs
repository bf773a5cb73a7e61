// Validate a .glb/.gltf with the Khronos glTF-Validator and print its report as JSON on stdout
// (docs/gltf_probes.md "Blender"): node tools/gltf_validate/validate.mjs FILE
// The validator is the npm package `gltf-validator`, pinned in web/package.json's
// devDependencies (installed with `npm ci --prefix web`); VOXGI_GLTF_VALIDATOR_PACKAGE may name
// another package.json whose node_modules hold it. External buffers and images are read
// relative to FILE. Exit status: 0 when the report was printed, 2 on a usage or read error.
import fs from 'node:fs';
import path from 'node:path';
import { createRequire } from 'node:module';
import { fileURLToPath } from 'node:url';

const here = path.dirname( fileURLToPath( import.meta.url ) );
const packageJson = process.env.VOXGI_GLTF_VALIDATOR_PACKAGE || path.resolve( here, '..', '..', 'web', 'package.json' );
const validator = createRequire( packageJson )( 'gltf-validator' );

const file = process.argv[ 2 ];
if ( ! file ) {

	console.error( 'usage: node validate.mjs FILE.glb|FILE.gltf' );
	process.exit( 2 );

}

let bytes;
try {

	bytes = new Uint8Array( fs.readFileSync( file ) );

} catch ( error ) {

	console.error( `cannot read ${file}: ${error.message}` );
	process.exit( 2 );

}

const report = await validator.validateBytes( bytes, {
	uri: path.basename( file ),
	maxIssues: 0, // report every issue
	externalResourceFunction: ( uri ) => new Promise( ( resolve, reject ) => {

		fs.readFile( path.resolve( path.dirname( file ), decodeURIComponent( uri ) ), ( error, data ) => {

			if ( error ) reject( error.toString() );
			else resolve( new Uint8Array( data ) );

		} );

	} ),
} );
process.stdout.write( JSON.stringify( report ) + '\n' );
